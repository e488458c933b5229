"""The project's exceptions: one root, subclasses that also inherit the matching builtin.

Messages state what was expected, what was found, and what to do about it.
"""


class TiledSimplifyError(Exception):
    """Root of every error raised on purpose by tiledsimplify."""


class InputError(TiledSimplifyError, ValueError):
    """The points, masks or options given are not usable as they are."""


class BudgetWarning(UserWarning):
    """The requested count could not be reached exactly (e.g. too many boundary/frozen points)."""


class FileFormatError(TiledSimplifyError, ValueError):
    """A file exists but its content is not what its format promises."""
