"""tiledsimplify: feature-preserving simplification of huge 3-D point clouds.

Implements Song & Feng, "A point cloud simplification algorithm for mechanical part
inspection": sharp-edge (boundary) points are found and kept, then the least important point is
removed repeatedly, with exact local updates, until the requested size is reached.
"""

from .core import SimplifyOptions, SimplifyResult, simplify_points
from .errors import BudgetWarning, InputError, TiledSimplifyError


def run(*args, **kwargs):
    """The tiled pipeline; see :func:`tiledsimplify.pipeline.run` (imports dask lazily)."""
    from .pipeline import run as _run
    return _run(*args, **kwargs)

__version__ = "0.1.0"

__all__ = [
    "BudgetWarning",
    "InputError",
    "SimplifyOptions",
    "SimplifyResult",
    "TiledSimplifyError",
    "run",
    "simplify_points",
    "__version__",
]
