"""Data-set shards as Ray tasks (``nbrdf data ... --ray auto|local|ADDRESS``).

Ray (an existing distributed engine) runs the shard function it is given
(``dataset.make_shard``: this module does not import the data set) for every
shard that is not on disk yet; the driver writes each result atomically as it
arrives, so the output folder lives on the driver only, an interrupted run
resumes like a local one, and a shard is byte-for-byte the shard a local run
makes (its random streams derive from (seed, split, class, index) alone and
the Monte Carlo walk does not depend on the number of threads).

Addresses: ``"auto"`` joins the cluster Ray finds on this machine (``ray
start --head`` ran here, or ``RAY_ADDRESS``); ``"local"`` starts a private
local instance for this run; anything else is a cluster address
(``HOST:PORT`` of the head's GCS, or ``ray://HOST:PORT`` for Ray Client). An
address that cannot be reached ends in one ``NbrdfError`` line after at most
``CONNECT_TIMEOUT_S`` seconds, never a hang. If Ray is already initialised in
this process (a test, a notebook) that instance is used as it is.
"""
from __future__ import annotations

import socket
from typing import Callable

from nbrdf.neural.errors import NbrdfError

#: Seconds allowed to open a TCP connection to a given address before Ray is asked to join it.
CONNECT_TIMEOUT_S = 5.0


def _host_port(address: str) -> tuple[str, int]:
    rest = address.split("://", 1)[-1]
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit():
        raise NbrdfError(f"--ray {address}: not a Ray address (auto, local, HOST:PORT or ray://HOST:PORT)")
    return host.strip("[]"), int(port)


def _reachable(address: str) -> None:
    host, port = _host_port(address)
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as e:
        raise NbrdfError(f"--ray {address}: cannot reach the Ray cluster ({e.strerror or e})") from None


def connect(address: str):
    """Initialises Ray for ``address`` (see the module doc) and returns the module."""
    try:
        import ray  # optional: ray (the cluster extra)
    except ImportError:
        raise NbrdfError("--ray needs Ray: pip install 'nbrdf[cluster]'") from None
    if ray.is_initialized():
        return ray
    kw = dict(include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    try:
        if address == "local":
            ray.init(**kw)
        elif address == "auto":
            ray.init(address="auto", **kw)
        else:
            _reachable(address)
            ray.init(address=address, **kw)
    except NbrdfError:
        raise
    except Exception as e:  # Ray raises ConnectionError, RuntimeError, ValueError... by version
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise NbrdfError(f"--ray {address}: cannot join the Ray cluster ({msg})") from None
    return ray


def run_shards(make_shard: Callable[[object, object], dict], cfg, shards: list, address: str,
               write: Callable[[object, dict], None], on_done: Callable[[object], None] = lambda s: None) -> None:
    """Runs ``make_shard(cfg, s)`` (a module-level function, so Ray ships it
    by reference) for every shard as one Ray task each and hands every result
    to ``write(shard, arrays)`` (then ``on_done(shard)``) in completion order.
    Errors raised inside a task reach the caller."""
    ray = connect(address)
    task = ray.remote(num_cpus=1)(_make_shard_task)  # one CPU per task: the walk runs one thread there
    pending = {task.remote(make_shard, cfg, s): s for s in shards}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                s = pending.pop(ref)
                try:
                    arrays = ray.get(ref)
                except Exception as e:
                    cause = getattr(e, "cause", None)
                    if isinstance(cause, NbrdfError):
                        raise cause from None
                    raise
                write(s, arrays)
                on_done(s)
    finally:
        for ref in pending:
            ray.cancel(ref)


def _make_shard_task(make_shard, cfg, shard):
    """One shard in a Ray worker: the walk on the one CPU Ray granted (the
    result does not depend on it)."""
    import numba  # late: numba costs ~0.4 s; only a Ray worker sets its threads

    numba.set_num_threads(1)
    return make_shard(cfg, shard)
