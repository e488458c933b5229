"""The result of one simplification: kept points, flags, and the full progressive order."""

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError


@dataclass
class SimplifyResult:
    """What :func:`~tiledsimplify.simplify_points` returns.

    Attributes
    ----------
    keep : bool (n,)
        Points kept at the requested count (frozen points always are; ``features`` are sure
        of up to ``options.edge_share`` of it).
    boundary : bool (n,)
        Points flagged on or near a sharp edge: in mode ``"coverage"`` within one cloud spacing
        (``edge_width``) of the line of one of their nearest fits on a sharp edge or crease
        (reported: the LAS ``sharp_edge`` dimension). The flags change no kept point: what is
        kept is decided by the ``features``.
    features : bool (n,)
        The points the simplification treats as edge points: in mode ``"coverage"`` those
        within about one spacing of every line a two-plane fit found — the flags' sharp edges
        and also narrow smooth folds (a fillet a few spacings across: at the kept spacing an
        edge too, but not a sharp one; :mod:`tiledsimplify.core.edge_fit`, "Smooth folds") —
        but beside a crease only its soft band; and, where the count has room for their
        cover, regions of detail finer than the spacing that no line explains (a threaded
        hole; :func:`tiledsimplify.core.unresolved.regions`); in mode
        ``"paper"`` the flags. Up to
        ``options.edge_share`` of the count they are sure of being kept (never removed by the
        greedy): all of them if they fit, else an even sample along the lines — of the
        ``band`` alone where the band does not fit; the others compete with the rest, and the
        gap refinement keeps each within a cover radius of a kept point.
    band : bool (n,)
        The feature points nearest each line (mode ``"coverage"``: within
        ``options.edge_width`` local spacings of a fitted or borrowed two-plane line, 0.7 of
        that beside a soft edge — not the points a corner's three-plane fit flags,
        :func:`tiledsimplify.core.edge_fit._fit_corner`; mode ``"paper"``: every flagged
        point): sampled first for the sure points, and never swapped out by the gap
        refinement once kept (:func:`tiledsimplify.core.refine.edge_cover_radius`;
        :mod:`tiledsimplify.core.edge_fit`, step 4).
    protected : bool (n,)
        The points the gap refinement never swaps out for their boundary measure once kept
        (:func:`tiledsimplify.core.refine.protected`: well above the threshold, with a point
        that is not within two steps of the Voronoi lists).
    normals : float64 (n, 3)
        Unit normals of the input points (estimated on the full input).
    rank : int64 (n,)
        Removal order up to the requested count: 0 = removed first; -1 = kept.
    importance : float64 (n,)
        Importance at the moment of removal; NaN for kept points.
    deviation : float64 (n,)
        The boundary measure of every point, and ``threshold`` the value it was cut at.
    order, order_importance : int64 (r,), float64 (r,)
        The full progressive removal sequence (past the target if ``options.progressive``):
        point ids and their importance at removal.
    target : int
        The requested count (with only a ``max_spacing`` guard and no count asked, the count
        the guard reached); ``count`` the number actually kept; ``reached`` whether they are
        equal, and ``message`` why not.
    """

    keep: np.ndarray
    boundary: np.ndarray
    normals: np.ndarray
    rank: np.ndarray
    importance: np.ndarray
    deviation: np.ndarray
    threshold: float
    order: np.ndarray
    order_importance: np.ndarray
    target: int
    message: str = ""
    stats: dict = field(default_factory=dict)
    band: np.ndarray | None = None
    features: np.ndarray | None = None
    protected: np.ndarray | None = None

    @property
    def n(self):
        return int(self.keep.size)

    @property
    def count(self):
        return int(np.count_nonzero(self.keep))

    @property
    def reached(self):
        return self.count == self.target

    def keep_at(self, ratio=None, *, count=None):
        """The kept mask at another count, from the recorded order (no recomputation).

        Any count between ``n - len(order)`` (everything removable removed) and ``n`` is
        exact: the greedy sequence does not depend on where it stops.
        """
        target = resolve_target(self.n, ratio, count)
        floor = self.n - self.order.size
        if target < floor:
            raise InputError(
                f"keep_at: {target} points asked, but only {self.order.size} of {self.n} were "
                f"removed in this run, so at least {floor} remain: frozen points and the "
                "boundary points sure of being kept are never removed, and a run with "
                "options.progressive=False or progressive_until stops early. Ask for that many "
                "or more, or run simplify_points again with the smaller target.")
        keep = np.ones(self.n, dtype=bool)
        keep[self.order[: self.n - target]] = False
        return keep


def short_message(target, n, must, kept, boundary, vetoed, guard, frozen=None):
    """Why ``kept`` points of ``n`` stay, not ``target``: ``must`` had to — ``boundary``
    boundary points, ``frozen`` frozen ones (if given) and ``vetoed`` that the ``guard`` rule
    vetoed. The text of :attr:`SimplifyResult.message` and of a tiled run's summary."""
    why = f"{boundary} boundary"
    if frozen is not None:
        why += f", {frozen} frozen, overlapping ones counted once"
    if vetoed:
        why += f"; {vetoed} vetoed by the {guard} guard"
    # the advice for what kept the most first; none for a cause that kept nothing
    flags = ("give options.edge_share a share of the count (such as 0.5) to keep only that "
             "many boundary points for certain, or raise options.boundary_threshold to flag "
             "fewer")
    fixes = [(vetoed, "raise options.max_spacing"), (boundary or not vetoed, flags)]
    fixes = [fix for count, fix in sorted(fixes, key=lambda f: -f[0]) if count]
    return (f"asked to keep {target} of {n} points, but {must} must be kept ({why}): kept "
            f"{kept}. Raise the target, or " + ", or ".join(fixes) + ".")


def nothing_kept(n, ratio, target):
    """The warning where a ``ratio`` keeps no point of ``n`` (its product rounds to 0: a
    ratio of 0.2 of 2 points), so the output would be empty; ``""`` otherwise (an explicit
    ``count=0`` is taken as meant)."""
    if ratio is None or target != 0 or n == 0:
        return ""
    return (f"ratio {float(ratio):g} of {n:,} points keeps no point ({float(ratio) * n:.3g} "
            "rounds to 0): the output is empty; ask a larger ratio, or a count")


def resolve_target(n, ratio, count, guard=None):
    """The target count from exactly one of ``ratio`` (0..1] or ``count`` (0..n) — or None
    from neither where the caller takes ``guard`` (the options' guard rule) and it is
    ``"max_spacing"``: then the guard sets the count (as few points as its limit allows)."""
    if ratio is None and count is None and guard == "max_spacing":
        return None
    if (ratio is None) == (count is None):
        raise InputError("give exactly one of ratio= (fraction of points to keep, in (0, 1]) "
                         f"or count= (number of points to keep); got ratio={ratio!r}, "
                         f"count={count!r}." + (
                             " (Or neither, with options.guard='max_spacing': as few points as "
                             "options.max_spacing allows.)"
                             if ratio is None and guard is not None else ""))
    if ratio is not None:
        r = float(ratio)
        if not 0.0 < r <= 1.0:
            raise InputError(f"ratio must be in (0, 1], got {ratio!r}; use count= for an "
                             "absolute number of points.")
        return int(round(r * n))
    try:  # NaN and inf: int() raised ValueError / OverflowError without naming count
        c = int(count)
    except (TypeError, ValueError, OverflowError):
        c = None
    if c is None or c != count or not 0 <= c <= n:
        raise InputError(f"count must be an integer between 0 and the number of points ({n}),"
                         f" got {count!r}.")
    return c
