"""The ingest's planning sample and the spacing estimated from it.

Each point's key is a seeded hash of its global index (:func:`sample_keys`); the sample is
the points of the ``k`` smallest keys (:class:`BottomK`), so it depends on the set of points
and the seed only, not on how the input is chunked or cut into parts. A part may keep only
keys below :func:`key_limit`. The cloud's spacing is estimated from the sample
(:func:`estimate_spacing`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def mix64(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser: a bijective, well-mixed hash of uint64 values (wraps mod 2**64)."""
    x = x.astype(np.uint64, copy=True)
    x += np.uint64(0x9E3779B97F4A7C15)
    x ^= x >> np.uint64(30)
    x *= np.uint64(0xBF58476D1CE4E5B9)
    x ^= x >> np.uint64(27)
    x *= np.uint64(0x94D049BB133111EB)
    x ^= x >> np.uint64(31)
    return x


def sample_keys(index: np.ndarray, seed: int) -> np.ndarray:
    salt = mix64(np.array([seed & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64))[0]
    return mix64(index.astype(np.uint64) ^ salt)


def estimate_spacing(sample_xyz: np.ndarray, n_total: int) -> tuple[float, float]:
    """Estimate the typical point spacing of the whole cloud from a uniform sample.

    The median distance from each sample point to its nearest other sample point, ``d_s``, is
    measured with a kd-tree. A sample of ``s`` of the ``n`` points is ``n / s`` times sparser
    than the cloud; for a *surface-like* cloud (a scan: points on 2-D surfaces) spacing scales
    as ``density ** -1/2``, so the cloud's spacing is estimated as ``d_s * sqrt(s / n)``. (For a
    volume-filling cloud the true factor is ``(s / n) ** (1/3)`` and this underestimates; for
    curve-like data it overestimates.) Zero distances (duplicate points) are ignored when the
    median would otherwise be zero.

    Parameters
    ----------
    sample_xyz : ndarray, shape (s, 3)
        Uniform random sample of the cloud.
    n_total : int
        Number of points of the cloud.

    Returns
    -------
    spacing : float
        Estimated median nearest-neighbour spacing of the whole cloud (0 if it cannot be
        estimated: fewer than 2 distinct points).
    sample_median : float
        The measured median nearest-neighbour distance within the sample, ``d_s``.
    """
    s = sample_xyz.shape[0]
    if s < 2:
        return 0.0, 0.0
    d, _ = cKDTree(sample_xyz).query(sample_xyz, k=2, workers=-1)
    d = d[:, 1]
    med = float(np.median(d))
    if med == 0.0:
        pos = d[d > 0]
        med = float(np.median(pos)) if pos.size else 0.0
    return med * float(np.sqrt(min(1.0, s / max(int(n_total), 1)))), med


class BottomK:
    """Uniform sample without replacement of bounded size: keep the k smallest hash keys.

    Each point's key is a seeded hash of its global index, so the sample depends only on the
    set of points and the seed, not on chunk sizes or chunk order. A sample of one part of
    the input may keep only keys below ``limit`` (:func:`key_limit`): the k smallest keys of
    the whole input lie below it (checked when the parts' samples are merged).
    """

    def __init__(self, k: int, seed: int, limit: int | None = None):
        self.k, self.seed = k, seed
        self.limit = None if limit is None else np.uint64(limit)
        self.keys = np.zeros(0, dtype=np.uint64)
        self.xyz = np.zeros((0, 3))
        self.index = np.zeros(0, dtype=np.int64)

    def add(self, start: int, xyz: np.ndarray):
        """Add a chunk's points (global indices from ``start``). Only its own ``k`` smallest
        keys below the bounds can enter the sample, so they are picked from the keys before
        any coordinate is gathered: a chunk of 1M points copied 40 MB of them into the merge
        before, its first ``add`` in a fresh process 0.26 s against 0.03 s for the same chunk
        again (new memory is slow to touch on these machines: docs/measurements.md, "Memory
        new to a process")."""
        keys = sample_keys(np.arange(start, start + xyz.shape[0], dtype=np.int64), self.seed)
        below = self.limit
        if self.keys.size >= self.k:
            top = self.keys.max()
            below = top if below is None else min(below, top)
        sel = np.arange(keys.size) if below is None else np.flatnonzero(keys < below)
        if sel.size > self.k:
            sel = sel[np.argpartition(keys[sel], self.k - 1)[: self.k]]
        self.merge(keys[sel], start + sel, xyz[sel])

    def merge(self, keys: np.ndarray, idx: np.ndarray, xyz: np.ndarray):
        """Add points with their keys (another sample's ``keys``, ``index``, ``xyz``)."""
        if self.limit is not None:
            keep = keys < self.limit
            keys, idx, xyz = keys[keep], idx[keep], xyz[keep]
        if self.keys.size >= self.k:
            keep = keys < self.keys.max()
            keys, idx, xyz = keys[keep], idx[keep], xyz[keep]
        if not keys.size:
            return
        keys = np.concatenate([self.keys, keys])
        idx = np.concatenate([self.index, idx])
        xyz = np.concatenate([self.xyz, xyz])
        if keys.size > self.k:
            sel = np.argpartition(keys, self.k - 1)[: self.k]
            keys, idx, xyz = keys[sel], idx[sel], xyz[sel]
        self.keys, self.index, self.xyz = keys, idx, xyz

    def result(self) -> np.ndarray:
        order = np.argsort(self.index, kind="stable")
        return self.xyz[order]


def key_limit(k: int, n: int | None) -> int | None:
    """A key below which the ``k`` smallest of ``n`` uniform 64-bit keys lie but for a chance
    of ~1e-15 (8 standard deviations and 64 keys of margin); None when that is no limit."""
    if n is None or n <= 0:
        return None
    want = k + 8.0 * np.sqrt(k) + 64.0
    if want >= n:
        return None
    return int(want / n * 2.0 ** 64)
