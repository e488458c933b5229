"""Real scans the benchmarks share: the Stanford Bunny's ten raw range scans, registered.

``shared/data/scans/stanford_bunny_range``: ten Cyberware 3030MS range scans of the Bunny
(362,272 points in all, metres), each in its scanner's frame, and ``bun.conf``, whose
``bmesh NAME tx ty tz qi qj qk qr`` lines place each scan. A scan's points go to the common
frame as ``R(q)⁻¹ p + t`` (checked: the other nine scans then lie a median 0.23 mm from
bun000's points, spacing 0.52 mm; with ``R(q) p + t`` 8 mm). Overlapping views, registration
residue and scanner noise: what a real multi-view scan brings.
"""

from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
BUNNY_RANGE = DATA / "scans" / "stanford_bunny_range"


def bunny_range(folder=BUNNY_RANGE):
    """The ten range scans in one frame, in ``bun.conf``'s order: float64 (362272, 3)."""
    from scipy.spatial.transform import Rotation

    from tiledsimplify.io import read_points
    parts = []
    for line in (Path(folder) / "bun.conf").read_text().splitlines():
        f = line.split()
        if f and f[0] == "bmesh":
            t, q = np.array(f[2:5], float), np.array(f[5:9], float)
            P = read_points(Path(folder) / (f[1] + ".gz"))
            parts.append(Rotation.from_quat(q).inv().apply(P) + t)
    return np.vstack(parts)
