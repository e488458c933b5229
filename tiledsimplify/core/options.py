"""Options of the core simplification, validated once."""

import numbers
from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError
from .boundary import FLOOR, K_SIGMA
from .edge_fit import MIN_ANGLE, WIDTH
from .importance import MEASURES
from .removal import GUARDS

#: the modes, default first
MODES = ("coverage", "paper")
#: default strength of the coverage term (see :mod:`.importance`). Measured on the 37 quality
#: cases (Bunny, 12 CAD parts even and as scans at noise 0.1 and 0.2; ratio 0.1 / 0.2) against
#: 1: strength 3 lowers the mean surface error on 31 of 37 (geometric mean -0.8 %), edge
#: coverage up on 21 of 36 (+0.9 %), Hausdorff -0.4 %; 10, 30 and 100 about the same as 3
#: (mean -1.1 to -1.3 %, but lower on fewer cases: 27-30 of 37) — past ~3 Eq. (1) only
#: orders points of about equal spacing, while the edges it cannot see are kept as flags
COVERAGE = 3.0
#: mode "coverage": default reach of the Voronoi neighbourhoods, in spacings. 12 instead of 20
#: (2026-11-23): mean Voronoi degree 13.9 -> ~12 on the Bunny, and the removal's facet tests
#: go with the square of the link; whole calls 12-18 % faster (``benchmarks/reach_speed.py``,
#: fastest of 3: the Bunny at 10 % 1.97 -> 1.62 s, 100k scan points 4.15 -> 3.53 s, 36k
#: Bunny-range points 1.77 -> 1.55 s). On the 37 quality cases:
#: every target count as at 20 (mean error below every peer on one case more), geometric
#: means of mean error 1.000, Hausdorff 0.998, edge coverage 0.997, F1 0.997. 10 was faster
#: still (the Bunny 1.52 s) but cost the line scans 1-2 points of edge coverage (their
#: spacing, the median nearest distance, is along the lines, 4x closer than across them).
REACH = 12.0
#: mode "coverage": default pre-thinning, in multiples of the target count (:mod:`.prethin`).
#: 2 instead of 3 (2026-12-04, with the protected points thinned like the rest): the 20 %
#: quality cases now thin too (a subset of 0.4 of the cloud, under ``MAX_SHARE``), and
#: against no thinning, over the 38 quality cases, geometric means of mean error 0.994,
#: Hausdorff 0.993, edge coverage 0.993, time 0.71; every target count kept, mean error below
#: every peer on one scan more; the Bunny 17.16 -> 17.12, Hausdorff 140.8 -> 139.7. 1.5: edge
#: coverage another -0.6 %, mean error +0.2 %, 8 % faster
PRETHIN = 2.0
#: mode "coverage": default ``edge_share``, the most of the count flagged points are sure of.
#: Measured 2026-12-05 on the 39 quality cases (``benchmarks/quality.py``, ours only, against
#: no limit): at 0.5 four even CAD parts change (their flags are 0.50-0.88 of the count), mean
#: surface error and Hausdorff lower on all four (octagonal_pocket 34.0 -> 21.9, below every
#: peer's 23.7; Hausdorff 218 -> 125), edge coverage up on three; at 0.4 six change (Fandisk,
#: block and angle_block too): Hausdorff within 1.2x the best peer's on all 12 even parts, not
#: 6 (Fandisk 155 -> 144, best 125), mean error still the lowest on each (Fandisk 6.27 -> 6.59,
#: best peer 13.3), edge coverage at most 0.027 lower (idler_riser 0.942 -> 0.915, best peer
#: 0.905); at 0.35 the Bunny changes too (mean 17.13 -> 16.27) but idler_riser's edge coverage
#: falls below CGAL hierarchy's and octagonal_pocket's below 0.95. At 5 % kept (7 cases with
#: the peers) 0.4 keeps the lowest mean error on 6 (0.5: 5) and Hausdorff within 1.18x the
#: best peer's on all 7 (0.5: 5). Scans, the Bunny range scans and Autzen: unchanged. (Those
#: runs drew the share from the band alone; drawn from every flag, later that day, 0.45 lost
#: six Hausdorff targets and 0.35 idler_riser's edge-coverage lead: docs/measurements.md.)
EDGE_SHARE = 0.4


@dataclass(frozen=True)
class SimplifyOptions:
    """How :func:`~tiledsimplify.simplify_points` decides what to keep.

    Parameters
    ----------
    mode : {"coverage", "paper"}
        ``"coverage"`` (default): thin boundary flags — the paper's normal-deviation measure
        over a two-ring, then each candidate kept only within ``edge_width`` spacings of the
        edge line fitted to it (:mod:`tiledsimplify.core.edge_fit`) — and greedy removal by
        Eq. (1) plus the hole a removal would open (importance ``"coverage"``): no emptied
        faces. ``"paper"``: Song & Feng's algorithm as published — boundary points flagged by
        normal deviation over the one-ring with an automatic threshold, greedy removal by
        Eq. (1); it empties flat faces and flags a band several spacings wide.
    importance : {"paper", "coverage"} or None
        The importance measure (see :mod:`tiledsimplify.core.importance`); None: the mode's.
    detect_boundary : bool
        Flag and keep sharp-edge points (paper §3.1). False treats every point as smooth.
    boundary_threshold : float or None
        Fixed threshold on the normal-deviation measure (``"coverage"``: on the two-ring
        measure, default 0.08 rad; ``"paper"``: None finds it automatically).
    boundary_k : float
        ``"paper"`` automatic threshold: robust standard deviations above the median.
    boundary_floor : float
        ``"paper"`` automatic threshold: lower bound (radians).
    edge_width : float
        ``"coverage"``: flag candidates within this many local spacings of the fitted edge
        (0.7 of it beside edges whose faces fold by less than 60°, :func:`.edge_fit.band`;
        0.5 of it from a neighbour's edge where a candidate's own fit does not flag it,
        :func:`.edge_lines.borrow`).
    edge_angle : float
        ``"coverage"``: the least fold, in degrees, of a sharp edge: where the two faces fitted
        around a candidate fold by less (the angle between their planes), it is not flagged.
        Wedges whose faces meet at less than this angle are not found either, so at most 90.
        Default 40 (:data:`.edge_fit.MIN_ANGLE`, measured against 35 and 45); lower it for
        parts whose features fold by 30-40° (chamfers, shallow bevels): more of them flagged,
        and more flags on fillets and noisy scans.
    coverage : float
        Strength of the coverage term: the importance is Eq. (1) + ``coverage / (3 · spacing)
        · ρ²`` (ρ²: mean squared distance to the local-mesh neighbours). Larger: more even
        spacing; smaller: more points moved to curved regions.
    spacing : float or None
        The input's typical point spacing in model units, which scales the coverage term.
        None: the median nearest-neighbour distance of the input. (A tiled run passes one
        value to every tile.)
    reach : float or None
        Voronoi neighbours ``VN_p`` are the points whose Voronoi cell shares a facet with
        ``p``'s *within this many spacings of both* (the facet's part inside the two balls of
        radius ``reach · spacing``, as in an alpha complex). ``inf``: the paper's unbounded
        rule. None: the mode's — 12 for ``"coverage"``, ``inf`` for ``"paper"``. Neighbours
        whose shared facet comes within the reach are unchanged; it cuts the ones a point gets
        only through the far reaches of its cell — across the inside of a part, and, on the
        outside of a flat face of a quantised scan, hundreds to thousands (one 100k-point tile
        of a 10M scan: removal ~165 s unbounded, ~3 s at 20) — and bridges no gap wider than
        twice the reach (a point with no neighbour left is kept to the end).
    guard : {"none", "max_spacing"}
        A rule that can veto a removal (see :mod:`tiledsimplify.core.removal`). Vetoed
        points are kept; if that makes the target unreachable the result says so.
    max_spacing : float or None
        For ``guard="max_spacing"`` (and refused without it): no input point is left farther
        than this distance (model units) from a kept point, at every count of the removal
        sequence. Each removed point is covered by a remaining one within the distance; a
        removal is vetoed unless the point and every point it covers can be handed to a
        remaining Voronoi neighbour within it (:func:`tiledsimplify.core.removal.guard_allows`).
        In a tiled run a tile's points are covered by its own points only (its halo's own tiles
        may remove them). Until 2026-12-04 the rule only asked for a remaining neighbour of the
        removed point within the distance, which bounded nothing: the Bunny at 5 spacings had
        points 7 spacings from every kept one, 8.8 in a tiled run.
    progressive : bool
        Keep removing past the target (recording rank and importance) until only boundary and
        frozen points remain, so :meth:`SimplifyResult.keep_at` can answer any coarser count.
        The kept set at the target is the same either way; False is ~10 % faster at ratio 0.1.
    progressive_until : float or None
        With ``progressive``: past the target, stop right after the first removal whose
        importance exceeds this level. The recorded order then holds, exactly as in a run to
        the end, every step whose running maximum of importance at removal is at most the
        level — what a tiled run needs to cut all tiles at one level — without the end of the
        sequence, which is the slow part on flat faces (the points around an emptied face
        become Voronoi neighbours of each other). None runs to the end.
    refine : bool or None
        After the greedy removal reaches the target, swap kept points for removed ones at equal
        count while that lowers the Hausdorff distance from the input to the kept set
        (:mod:`tiledsimplify.core.refine`); boundary, frozen and kept points whose boundary
        measure is above ``refine.PROTECT`` (3) times the threshold are never swapped out.
        Only the kept set at the requested count is refined: ``order`` and
        :meth:`SimplifyResult.keep_at` stay the greedy's. None: the mode's default
        (``"coverage"``: True; ``"paper"``: False). With a ``max_spacing`` guard as well (it
        never raises the Hausdorff distance, so the bound holds; until 2026-12-04 it was off
        with a guard, so a limit that never bound still cost the refined quality).
    update_normals : bool or None
        After each removal, recompute the normals of the removed point's former neighbours
        from their new local meshes, and so the importance of every point whose Eq. (1) reads
        one of them (paper §3.3, Fig. 1: the second ring). False keeps every point's normal
        from the whole cloud (the local meshes and the first ring's importance are still
        updated exactly). None: the mode's default (``"paper"``: True; ``"coverage"``: False —
        the same quality over the 38 quality cases, geometric means Hausdorff +0.1 %, mean
        error −0.1 %, for a removal loop ~25 % faster).
    prethin : float or None
        Before the greedy removal, thin the smooth points to about this many times the target
        count by a Poisson-disk sample along the neighbourhood graph (boundary and frozen
        points all stay, strongly curved ones are drawn first), and run the greedy on that
        subset (:mod:`tiledsimplify.core.prethin`): most removals at small targets are on
        smooth surface, where the greedy does little more than thin evenly. Only where the
        subset would be at most half the cloud (:data:`~tiledsimplify.core.prethin.MAX_SHARE`;
        at 2, targets up to a quarter): above that it costs what it saves. 0: off (every
        removal by the greedy, as the paper does). None: the mode's default (``"coverage"``: 2;
        ``"paper"``: 0). With a ``max_spacing`` guard the disks are at most
        ``prethin.GUARD_RADIUS`` of the limit, and each thinned point starts covered by its
        nearest kept one (:func:`tiledsimplify.core.prethin.covered_by`). Counts
        above the subset's (:meth:`SimplifyResult.keep_at`) come from
        the sample, not the greedy.
    edge_share : float or None
        ``"coverage"``: the most of the requested count that feature points
        (:attr:`SimplifyResult.features`: the flagged, sharp-edge ones and those on narrow
        smooth folds) are sure of. Where there are more, that many are kept for certain — an
        even sample along the lines, the points of the core band (:attr:`SimplifyResult.band`)
        nearest their fitted line first, of the band alone where it holds more than that
        (:func:`tiledsimplify.core.prethin.edge_sample`) — and the rest (still flagged where
        they are) compete with the rest of the cloud. At small targets the flags alone would
        otherwise take the whole count and leave the faces empty (Fandisk at 5 %: 1,524 flags
        for a count of 824, all kept: mean surface error 10x the best peer's). A value in (0,
        1], or
        ``inf``: every flagged point kept whatever the count (as until 2026-12-05; the count
        may then be missed). None: the mode's default (``"coverage"``: :data:`EDGE_SHARE`,
        0.4; ``"paper"``: ``inf``, as published). A tiled run applies it to each tile's share
        of the count (as the pre-thinning does). The share is of the count asked:
        :meth:`SimplifyResult.keep_at` a smaller count keeps the same sure points, a larger
        share of it.
    """

    mode: str = "coverage"
    importance: str | None = None
    detect_boundary: bool = True
    boundary_threshold: float | None = None
    boundary_k: float = K_SIGMA
    boundary_floor: float = FLOOR
    edge_width: float = WIDTH
    edge_angle: float = MIN_ANGLE
    coverage: float = COVERAGE
    spacing: float | None = None
    reach: float | None = None
    guard: str = "none"
    max_spacing: float | None = None
    progressive: bool = True
    progressive_until: float | None = None
    refine: bool | None = None
    update_normals: bool | None = None
    prethin: float | None = None
    edge_share: float | None = None

    def __post_init__(self):
        for f in fields(self):  # a config file can give any type: say which option is wrong
            value = getattr(self, f.name)
            kind = getattr(f.type, "__name__", None) or str(f.type)  # "float", "float | None"
            if value is None and "None" in kind:
                continue
            if kind.startswith("float") and (isinstance(value, bool)
                                             or not isinstance(value, numbers.Real)):
                raise InputError(f"options.{f.name} must be a number"
                                 f"{' or None' if 'None' in kind else ''}, got {value!r}.")
            if kind.startswith("bool"):
                if not isinstance(value, (bool, np.bool_)):
                    raise InputError(f"options.{f.name} must be true or false"
                                     f"{' or None' if 'None' in kind else ''}, got {value!r}.")
                object.__setattr__(self, f.name, bool(value))
            if kind.startswith("str") and not isinstance(value, str):
                raise InputError(f"options.{f.name} must be a name (a string), got {value!r}.")
        if self.mode not in MODES:
            raise InputError(f"options.mode must be one of {MODES}, got {self.mode!r}.")
        if self.importance is None:
            object.__setattr__(self, "importance", "paper" if self.mode == "paper" else "coverage")
        if self.refine is None:
            object.__setattr__(self, "refine", self.mode != "paper")
        if self.update_normals is None:
            object.__setattr__(self, "update_normals", self.mode == "paper")
        if self.importance not in MEASURES:
            raise InputError(
                f"options.importance must be one of {tuple(MEASURES)}, got {self.importance!r}.")
        if self.boundary_threshold is not None and not self.boundary_threshold >= 0:
            raise InputError("options.boundary_threshold must be a non-negative number or None,"
                             f" got {self.boundary_threshold!r}.")
        if self.guard not in GUARDS:
            raise InputError(f"options.guard must be one of {tuple(GUARDS)}, got {self.guard!r}.")
        if self.guard == "max_spacing" and not (
                self.max_spacing is not None and 0 < self.max_spacing < float("inf")):
            raise InputError("options.guard='max_spacing' needs options.max_spacing, a positive "
                             f"(finite) distance in model units; got {self.max_spacing!r}.")
        if self.guard != "max_spacing" and self.max_spacing is not None:  # was ignored
            raise InputError(f"options.max_spacing={self.max_spacing!r} is a bound only with "
                             "options.guard='max_spacing' (guard = \"max_spacing\" in a "
                             f"config's [simplify]), not with guard={self.guard!r}; set it, or "
                             "drop max_spacing.")
        for name in ("edge_width", "coverage"):
            if not 0 < getattr(self, name) < float("inf"):
                raise InputError(f"options.{name} must be a positive (finite) number, got "
                                 f"{getattr(self, name)!r}.")
        if not 0 < self.edge_angle <= 90:
            raise InputError("options.edge_angle must be a fold in degrees, above 0 and at most "
                             f"90 (default {MIN_ANGLE:g}), got {self.edge_angle!r}.")
        if self.spacing is not None and not 0 < self.spacing < float("inf"):
            raise InputError("options.spacing must be a positive (finite) distance in model "
                             f"units or None, got {self.spacing!r}.")
        if self.reach is not None and not self.reach > 0:
            raise InputError("options.reach must be a positive number of spacings, inf (the "
                             f"paper's unbounded neighbourhoods) or None, got {self.reach!r}.")
        if self.progressive_until is not None and not (
                self.progressive_until == self.progressive_until):  # not NaN
            raise InputError("options.progressive_until must be a number (an importance "
                             f"level) or None, got {self.progressive_until!r}.")
        if self.prethin is not None and not (self.prethin == 0
                                             or 1 <= self.prethin < float("inf")):
            raise InputError("options.prethin must be 0 (off), a multiple of the target of at "
                             f"least 1, or None (the mode's default), got {self.prethin!r}.")
        if self.edge_share is not None and not (0 < self.edge_share <= 1
                                                or self.edge_share == float("inf")):
            raise InputError("options.edge_share must be a share of the count in (0, 1], inf "
                             "(every flagged point kept whatever the count) or None (the "
                             f"mode's default), got {self.edge_share!r}.")
        if not self.boundary_k > 0:
            raise InputError(f"options.boundary_k must be positive, got {self.boundary_k!r}.")
        if not self.boundary_floor >= 0:
            raise InputError(
                f"options.boundary_floor must be non-negative, got {self.boundary_floor!r}.")

    @property
    def reach_spacings(self):
        """The reach in spacings: the option, else the mode's default."""
        if self.reach is not None:
            return float(self.reach)
        return float("inf") if self.mode == "paper" else REACH

    @property
    def prethin_factor(self):
        """The pre-thinning's multiple of the target: the option, else the mode's (with a
        ``max_spacing`` guard its disks are at most ``prethin.GUARD_RADIUS`` of the limit)."""
        if self.prethin is not None:
            return float(self.prethin)
        return 0.0 if self.mode == "paper" else PRETHIN

    @property
    def edge_share_value(self):
        """The share of the count flagged points are sure of: the option, else the mode's."""
        if self.edge_share is not None:
            return float(self.edge_share)
        return float("inf") if self.mode == "paper" else EDGE_SHARE

    @property
    def refines(self):
        """Whether the gap refinement applies: ``refine`` on. With a ``max_spacing`` guard too:
        its swaps never raise the Hausdorff distance (:mod:`.refine`; tiled,
        :mod:`tiledsimplify.pipeline.tile_refine`), so the guard's bound holds."""
        return self.refine

    @classmethod
    def from_mapping(cls, mapping):
        """Build from a dict (e.g. a TOML table), rejecting unknown keys by name."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(mapping) - known)
        if unknown:
            raise InputError(f"unknown simplify option(s) {unknown}; known: {sorted(known)}.")
        return cls(**mapping)
