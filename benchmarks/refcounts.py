"""Share of the core's time in numba's reference counting, per kernel (Linux ``perf``).

Numba counts an array (an atomic ``lock incq`` / ``lock decq`` on its reference count, in
``NRT_incref`` / ``NRT_decref``) whenever it is bound to a name its pruning cannot pair up: an
array argument of an inlined helper, the entry of a called helper, a view made in a loop, any
use of an array replaced inside a loop. Until 2026-12-03 that was 23-24 % of the core's perf
samples (docs/measurements.md, "Reference counts"); kernel loops are now written so that it
stays near zero (``_jit.jit_leaf``, no array replaced in a hot loop). This benchmark checks
that a change kept it so.

The core runs twice on a cloud of :mod:`core_speed` in a child process under
``perf record --call-graph dwarf,64``; a sample whose instruction lies in ``NRT_incref`` or
``NRT_decref`` is charged to the kernel that called it — read from the return address on top
of the sampled user stack (the two functions are leaves), and charged to the compiled kernel
whose code starts nearest below it (a kernel's library holds the helpers compiled into it).
Needs ``perf`` and ``/proc/sys/kernel/perf_event_paranoid`` at most 2.

    python benchmarks/refcounts.py                 # scan:100000
    python benchmarks/refcounts.py bunny:100000
"""

import bisect
import json
import re
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path


def child(kind, n, out):
    """Run the core twice and write the code addresses the parent needs to ``out``."""
    import gc

    from numba.core.registry import CPUDispatcher
    from numba.core.runtime import nrt

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from core_speed import cloud

    from tiledsimplify import SimplifyOptions, simplify_points
    simplify_points(cloud("flat", 2000), ratio=0.2)  # warm the JIT
    X = cloud(kind, n)
    for _ in range(2):
        simplify_points(X, ratio=0.2, options=SimplifyOptions(progressive=False))
    kernels = {}
    for obj in gc.get_objects():
        if isinstance(obj, CPUDispatcher):
            for cres in obj.overloads.values():
                name = cres.fndesc.llvm_func_name
                addr = cres.library.get_pointer_to_function(name)
                if addr:
                    kernels[addr] = f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"
    lib = nrt.rtsys.library
    Path(out).write_text(json.dumps({
        "incref": lib.get_pointer_to_function("NRT_incref"),
        "decref": lib.get_pointer_to_function("NRT_decref"),
        "kernels": sorted(kernels.items())}))


def samples(perf_data):
    """``(ip, return address)`` of every user-space sample (``perf script -D``)."""
    dump = subprocess.run(["perf", "script", "-i", perf_data, "-D", "--no-inline"],
                          capture_output=True, text=True, check=True).stdout
    raw, ip = bytearray(), None
    for line in dump.splitlines():
        if line.startswith(". ... raw event"):
            raw = bytearray()
            continue
        m = re.match(r"^\.  [0-9a-f]{4}:  ((?:[0-9a-f]{2} )+)", line)
        if m:
            raw += bytes.fromhex(m.group(1).replace(" ", ""))
            continue
        m = re.search(r"PERF_RECORD_SAMPLE\(IP, 0x2\): \d+/\d+: (0x[0-9a-f]+)", line)
        if m:
            ip = int(m.group(1), 16)
            continue
        m = re.search(r"ustack: size \d+, offset (0x[0-9a-f]+)", line)
        if m and ip is not None:
            off = int(m.group(1), 16) + 8  # past the stack dump's size word
            yield ip, int.from_bytes(raw[off:off + 8], "little")
            ip = None


def main(case):
    kind, _, n = case.partition(":")
    if shutil.which("perf") is None:
        sys.exit("refcounts.py needs Linux perf (apt-get install linux-perf)")
    with tempfile.TemporaryDirectory() as tmp:
        data, addrs = str(Path(tmp) / "perf.data"), Path(tmp) / "addrs.json"
        run = subprocess.run(["perf", "record", "-q", "-F", "2000", "--call-graph", "dwarf,64",
                              "-o", data, sys.executable, __file__, "--child", kind, n,
                              str(addrs)], capture_output=True, text=True, check=False)
        if run.returncode or not addrs.exists():
            sys.exit(f"perf record failed (perf_event_paranoid above 2?):\n{run.stderr[-2000:]}")
        info = json.loads(addrs.read_text())
        starts = [a for a, _ in info["kernels"]]
        names = [name for _, name in info["kernels"]]
        nrt = {info["incref"] >> 12, info["decref"] >> 12}  # one small page of stubs
        total, counted, by_kernel = 0, 0, Counter()
        for ip, ret in samples(data):
            total += 1
            if ip >> 12 in nrt:
                counted += 1
                k = bisect.bisect_right(starts, ret) - 1
                by_kernel[names[k] if k >= 0 else "?"] += 1
    print(f"{case}: {total:,} samples, {counted:,} in NRT_incref/NRT_decref "
          f"({100 * counted / max(total, 1):.1f} %)\n")
    print("| kernel (caller) | samples in reference counting | share of all samples |")
    print("|---|---:|---:|")
    for name, c in by_kernel.most_common(12):
        print(f"| {name} | {c:,} | {100 * c / max(total, 1):.1f} % |")


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):  # the usage, not a run of minutes
        sys.exit(print(__doc__))
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), sys.argv[4])
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else "scan:100000")
