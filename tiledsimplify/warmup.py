"""Which kernels the package calls, with which argument types: the record that
``tiledsimplify compile`` (:mod:`.core.compile_cache`) compiles ahead from.

``python -m tiledsimplify.warmup --record`` runs :func:`workloads` and rewrites
``core/kernel_signatures.txt``; run it after changing a kernel's arguments (the test suite says
when the file is stale). It lives here, not in ``core/``, because the workloads run the tiled
pipeline too.
"""

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .core import compile_cache


def workloads():
    """Small runs that reach every kernel the package calls, with the argument types it calls
    them with: the core in both modes (and without the progressive order) on a sphere, on a
    cube's faces with exact duplicates, on a flat plate (the 2-D Delaunay) and on a cube's
    faces sampled exactly and evenly (:mod:`.core.unresolved` runs on those only), at 10 %
    (under a quarter: the pre-thinning runs too); a tiled run in both modes (halo, global cut, gap
    refinement)."""
    from .core.simplify import simplify_points
    from .pipeline import run

    rng = np.random.default_rng(0)
    sphere = rng.normal(size=(1500, 3))
    sphere /= np.linalg.norm(sphere, axis=1)[:, None]
    cube = rng.random((1500, 3))
    cube[np.arange(1500), rng.integers(0, 3, 1500)] = rng.integers(0, 2, 1500)
    plate = np.c_[rng.random((800, 2)), np.zeros(800)]
    # a cube's faces, each a jittered grid on its plane: exact and even, as a CAD model
    # sampled (the detail test runs on such samplings only; an even sphere is not exact)
    g = (np.stack(np.meshgrid(np.arange(16), np.arange(16)), -1).reshape(-1, 2) + 0.5
         + rng.uniform(-0.2, 0.2, (256, 2))) / 16
    even = np.concatenate([np.insert(g, axis, side, axis=1)
                           for axis in range(3) for side in (0.0, 1.0)])
    for X in (sphere, np.r_[cube, cube[:50]], plate, even):
        for mode in ("coverage", "paper"):
            for progressive in (True, False):
                simplify_points(X, 0.1, options={"mode": mode, "progressive": progressive})
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "cloud.npy"
        np.save(src, np.r_[cube, rng.random((1500, 3)) * [1, 1, 0.01]])
        for mode in ("coverage", "paper"):
            run(str(src), str(Path(tmp) / f"out_{mode}.npy"), ratio=0.1, tile_points=1000,
                scheduler="synchronous", options={"mode": mode})


def called_kernels():
    """``{kernel: {signature repr, ...}}``: the top-level kernels :func:`workloads` calls.

    The workloads run twice, each in a fresh process: the first fills the cache, the second
    reports. Kernels a cached kernel calls come inside its cached code, so in the second
    process only the kernels called from Python have compiled signatures.
    """
    out = {}
    for _ in range(2):
        done = subprocess.run([sys.executable, "-m", "tiledsimplify.warmup", "--called"],
                              check=True, capture_output=True, text=True)
    for line in done.stdout.splitlines():
        kernel, sig = line.split("\t")
        out.setdefault(kernel, set()).add(sig)
    return out


def record():
    """Rewrite the recorded signatures from :func:`called_kernels`, each timed alone."""
    used = {}
    for kernel, sigs in called_kernels().items():
        for text in sigs:
            sig = compile_cache.parse_signature(text)
            if sig is None:
                raise SystemExit(f"{kernel}: signature {text} does not read back as numba "
                                 "types; give the kernel plain array and scalar arguments")
            used.setdefault(kernel, set()).add(sig)
    for kernel, seconds in compile_cache.write_signatures(used):
        print(f"{seconds:5.1f} s  {kernel}", flush=True)
    print(f"wrote {compile_cache.SIGNATURES}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv == ["--record"]:
        record()
    elif argv == ["--called"]:
        workloads()
        for kernel, sigs in sorted(compile_cache.used_signatures().items()):
            for sig in sigs:
                print(f"{kernel}\t{sig!r}")
    else:
        sys.exit("usage: python -m tiledsimplify.warmup --record")


if __name__ == "__main__":
    main()
