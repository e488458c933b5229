"""What a run needs of dask.distributed workers, checked before any work.

Tile tasks open the tile store by its path on the worker and write their results into it, so
on a cluster the store must sit on a file system every worker mounts at the same path, and
every worker must run the same tiledsimplify (and numba) as the client. Neither shows until a
tile task runs: a store under the client's ``/tmp`` failed after the whole ingest with
``no tile store at …`` from a worker, and a worker without the package with a traceback. Here
the client writes a marker file beside the store and asks every worker (``Client.run``) to
read it, to write a file of its own there, and to say which code it runs; a scheduler with no
worker is waited for a while and then named, instead of a run that waits forever.
"""

import hashlib
import logging
import os
import secrets
import socket
from pathlib import Path

from .. import __version__
from ..errors import InputError, TiledSimplifyError

log = logging.getLogger("tiledsimplify")

#: seconds a run waits for a first worker to join a scheduler that has none
WORKER_WAIT = 60.0


def code_id() -> str:
    """A digest of this tiledsimplify's sources and numba's version: equal on two machines
    when they run the same code (what a tile computes depends on nothing else installed)."""
    import numba
    here = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(here.rglob("*.py")):
        digest.update(str(path.relative_to(here)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def probe(directory: str, token: str) -> dict:
    """Run on a worker: whether it sees the marker ``token`` in ``directory`` and can write a
    file there, its host and its code (:func:`code_id`)."""
    d = Path(directory)
    try:
        sees = (d / f".tiledsimplify-probe-{token}").read_text() == token
    except OSError:
        sees = False
    write_error = ""
    if sees:
        mine = d / f".tiledsimplify-probe-{token}-{os.getpid()}-{secrets.token_hex(4)}"
        try:
            mine.write_text(token)
            mine.unlink()
        except OSError as exc:
            write_error = f"{type(exc).__name__}: {exc.strerror or exc}"
    return {"host": socket.gethostname(), "sees": sees, "write_error": write_error,
            "version": __version__, "code": code_id()}


def _wait_for_workers(client, address):
    if client.scheduler_info().get("workers"):
        return
    log.info("waiting up to %.0f s for a dask worker to join %s", WORKER_WAIT, address)
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT)
    except TimeoutError:
        raise TiledSimplifyError(
            f"{address}: the dask scheduler has no workers (none joined within "
            f"{WORKER_WAIT:.0f} s). Start them (`dask worker {address}` on each machine) and "
            "run again; --scheduler threads runs on this machine alone.") from None


def check_workers(client, directory, *, temporary: bool) -> int:
    """Check, before any work, that every worker of ``client`` can read and write files in
    ``directory`` (the tile store's) and runs this client's code; returns the worker count.

    ``temporary``: the store is the run's temporary one (the fix named differs). Raises
    :class:`~tiledsimplify.errors.InputError` naming each worker that cannot, with its host,
    and what to do. Workers that join later are not checked.
    """
    address = getattr(client.scheduler, "address", "the dask scheduler")
    _wait_for_workers(client, address)
    directory = Path(directory)
    token = secrets.token_hex(8)
    marker = directory / f".tiledsimplify-probe-{token}"
    marker.write_text(token)
    try:
        replies = client.run(probe, str(directory), token, on_error="return")
    finally:
        marker.unlink(missing_ok=True)
    mine = code_id()
    broken, blind, readonly, other = [], [], [], []
    for worker, got in sorted(replies.items()):
        if isinstance(got, BaseException):
            broken.append(f"{worker} ({type(got).__name__}: {got})")
        elif not got["sees"]:
            blind.append(f"{worker} on {got['host']}")
        elif got["write_error"]:
            readonly.append(f"{worker} on {got['host']} ({got['write_error']})")
        elif got["code"] != mine:
            other.append(f"{worker} on {got['host']} (tiledsimplify {got['version']}, "
                         f"sources {got['code']})")
    n = len(replies)
    if broken:
        raise InputError(
            f"{address}: {len(broken)} of {n} dask workers cannot run tiledsimplify's check: "
            f"{', '.join(broken)}. Install tiledsimplify in the workers' environment (the "
            "same version as here) and run again.")
    if blind:
        where = (f"the run's temporary tile store is made in {directory} on this machine "
                 f"({socket.gethostname()}); give --store DIR on a file system every worker "
                 "mounts at the same path (NFS, Lustre, …), or set TMPDIR to one"
                 if temporary else
                 "give --store on a file system every worker mounts at the same path (NFS, "
                 "Lustre, …)")
        raise InputError(
            f"{directory}: {len(blind)} of {n} dask workers cannot see the tile store's "
            f"directory ({', '.join(blind)}): tiles are read and written there by the "
            f"workers. {where[0].upper()}{where[1:]}.")
    if readonly:
        raise InputError(
            f"{directory}: {len(readonly)} of {n} dask workers cannot write in the tile "
            f"store's directory ({', '.join(readonly)}); let the workers' user write there, or "
            "give --store elsewhere.")
    if other:
        raise InputError(
            f"{address}: {len(other)} of {n} dask workers run other tiledsimplify code than "
            f"this client (tiledsimplify {__version__}, sources {mine}): {', '.join(other)}. "
            "Install the same tiledsimplify and numba on every worker and here: tiles computed "
            "by other code would not fit together.")
    return n
