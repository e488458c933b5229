"""The one numba decorator every kernel uses: compiled, GIL released, cached on disk.

``nogil=True`` lets dask threads run kernels truly in parallel; ``cache=True`` keeps the
compile cost to the first run on a machine.

Numba's cache checks only the source file of the cached function itself, not of the kernels
it calls from other modules: edit ``local_mesh.py`` and a cached ``remove_points`` keeps running
the old ``local_mesh``. So the cache lives in a directory named after a hash of every kernel
source file of the package; any edit or upgrade starts a fresh cache. The base directory is
``$NUMBA_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME`` (or ``~/.cache``) ``/tiledsimplify``.
"""

import hashlib
import os
from pathlib import Path

import numba


def sources_digest(root, pattern="*.py"):
    """sha256 (hex) of numba's version and of every file under ``root`` matching ``pattern``
    (``**/*.py`` for subfolders too): each one's path relative to ``root``, then its bytes.
    Names this package's kernel cache and, over the whole package, the code a cluster worker
    runs (:func:`tiledsimplify.pipeline.workers.code_id`)."""
    root = Path(root)
    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(root.glob(pattern)):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _cache_dir():
    digest = sources_digest(Path(__file__).resolve().parent)
    base = os.environ.get("NUMBA_CACHE_DIR")
    if base:
        root = Path(base)
    else:
        root = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tiledsimplify"
    return root / f"kernels-{digest[:16]}"


def _set_cache_dir():
    try:
        path = _cache_dir()
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # not writable: numba falls back to its own locations
    numba.config.CACHE_DIR = str(path)


_set_cache_dir()

#: numba's "numpy" error model: a float division by zero gives inf/nan as numpy's would,
#: instead of a check and a Python ZeroDivisionError around every division (the kernels guard
#: their divisors; the clipping, plane fits and importance divide in their inner loops).
#: Measured 2026-12-02, old and new code alternating in separate processes: median ratios
#: 0.95 (removal, 9 pairs of 3 runs, 100k scan points), 0.93 (whole call, 5 pairs, 100k Bunny
#: points), 0.96 (whole call, 10 pairs of 4 runs, the 36k Bunny at 10 %; 7 of 10 pairs
#: lower) — each within the machine's noise alone, the same way in all three; ranks identical.
ERROR_MODEL = "numpy"

jit = numba.njit(cache=True, nogil=True, error_model=ERROR_MODEL)

#: for small helpers inlined into the caller at numba's IR level. Each array argument of an
#: inlined copy is counted like a new name (an atomic increment and decrement per call), so
#: helpers with array arguments called in loops are leaves (:data:`jit_leaf`) instead; this
#: stays for scalar helpers and for the Delaunay predicates, whose counts numba pairs up.
jit_inline = numba.njit(cache=True, nogil=True, inline="always", error_model=ERROR_MODEL)

#: for helpers called inside the kernels' loops that never allocate an array: compiled without
#: numba's reference counting (``_nrt=False``). Their arrays are always the caller's, alive for
#: the whole call, yet numba counted each array argument of a call or of an inlined copy with
#: an atomic increment and decrement (the caller's loop kept them apart, out of reach of its
#: pruning): 23-24 % of the core's perf samples on 100k scan points (16-37 % by stage), and
#: ~10 % of its time (docs/measurements.md "Reference counts", 2026-12-03). A leaf may call
#: other leaves, and may make views (``a[i]``, ``a[s:e]``), but not new arrays.
jit_leaf = numba.njit(cache=True, nogil=True, error_model=ERROR_MODEL, _nrt=False)
