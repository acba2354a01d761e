"""Independent tasks on local processes or on a Dask cluster, results as they finish.

A campaign reconstructs one test folder per task; a Monte Carlo flies one
chunk of cases per task.  Both hand a picklable top-level function and its
inputs to `run_tasks`, which runs them in this process (one worker), on a
`ProcessPoolExecutor` of local processes, or, given a scheduler address, on
a Dask cluster through `distributed.Client.map` (the workers must have
cpas-ocp installed and see the same file paths).  A scheduler that cannot be
used is an `InputError` on ``--scheduler``; an address that is not one at all is
refused before any work (`scheduler_address`), not by Dask's parser after it, and
one whose scheme this installation's Dask cannot speak (``ucx://`` without its
back end) before a connection is tried (`usable_scheme`).
"""

from __future__ import annotations

import ipaddress
import os
import re
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from types import FrameType
from typing import TypeVar
from urllib.parse import urlsplit

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.compiled import abandon

T = TypeVar("T")
R = TypeVar("R")


# The schemes of Dask's communication back ends; an address without one is tcp.
SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")
_HOST_LABEL = re.compile(r"(?!-)[\w-]{1,63}(?<!-)")  # letters of any script: IDN names


def scheduler_address(text: str) -> str:
    """`text` if it is a Dask scheduler address, ``SCHEME://HOST[:PORT]`` (``HOST[:PORT]``
    meaning tcp; an IPv6 host in brackets; ``inproc://`` any name), else ValueError
    saying what is expected and what is wrong: checked before the work, where Dask's
    own parser fails only when the tasks are sent, with an internal error."""
    expected = (f"a Dask scheduler address SCHEME://HOST[:PORT] (SCHEME one of "
                f"{', '.join(SCHEMES)}); got {text!r}")
    if not text or any(c.isspace() or not c.isprintable() for c in text):
        raise ValueError(f"{expected}: empty, or with a space or a control character")
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    if scheme not in SCHEMES:
        raise ValueError(f"{expected}: unknown scheme {scheme!r}")
    if not rest:
        raise ValueError(f"{expected}: no host")
    if scheme == "inproc":
        return text
    try:
        parts = urlsplit(f"//{rest}")
        port = parts.port
    except ValueError as exc:  # brackets unbalanced, a port not a number or beyond 65535
        raise ValueError(f"{expected}: {exc}") from None
    if parts.path or parts.query or parts.fragment or "@" in parts.netloc:
        raise ValueError(f"{expected}: more than a host and a port")
    if port == 0 or parts.netloc.endswith(":"):
        raise ValueError(f"{expected}: a port from 1 to 65535")
    host = parts.hostname or ""
    if parts.netloc.startswith("["):
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise ValueError(f"{expected}: {host!r} in brackets is no IPv6 address") from None
    elif not (_is_ipv4(host) or _is_host_name(host)):
        raise ValueError(f"{expected}: {host!r} is no host name or IPv4 address")
    return text


def _is_ipv4(host: str) -> bool:
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        return False
    return True


def _is_host_name(host: str) -> bool:
    """Whether `host` is a DNS name: labels of letters (any script), digits, hyphens and
    underscores, a final dot allowed, the last label not all digits (an IPv4 address
    mistyped, 1.2.3.4.5, is no name)."""
    labels = host.removesuffix(".").split(".")
    return all(_HOST_LABEL.fullmatch(label) for label in labels) and not labels[-1].isdigit()


def run_tasks(fn: Callable[[T], R], items: Sequence[T], workers: int = 2,
              scheduler: str | None = None) -> Iterator[tuple[int, R]]:
    """(index into `items`, fn(item)) for every item, in the order the tasks finish: on the
    Dask scheduler at `scheduler` (e.g. ``tcp://host:8786``) if given, else on `workers`
    local processes (in this process when `workers` is 1)."""
    if scheduler:
        return _on_dask(fn, items, scheduler)
    return _on_processes(fn, items, workers)


def _on_processes(fn: Callable[[T], R], items: Sequence[T],
                  workers: int) -> Iterator[tuple[int, R]]:
    if workers <= 1 or len(items) <= 1:
        yield from enumerate(map(fn, items))
        return
    pool = ProcessPoolExecutor(max_workers=min(workers, len(items)),
                               initializer=_worker_signals)
    try:
        futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
        for future in as_completed(futures):
            yield futures[future], future.result()
    except BaseException:
        # An interrupt (or any error) ends the workers now, not after their running tasks
        # (the executor's own shutdown waits for those: minutes for a campaign).  There is
        # no public way to do so before Python 3.14's `terminate_workers`.
        for process in list((pool._processes or {}).values()):
            process.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown()


def _worker_signals() -> None:
    """A local worker leaves Ctrl-C to the command, which ends it (a terminal sends SIGINT to
    the whole process group), and dies quietly on SIGTERM: it must not run the command's
    handlers, inherited through fork, which would print its traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_stop)


def _worker_stop(signum: int, frame: FrameType | None) -> None:
    """End a local worker at once, leaving no compiler running (each runs in a process group
    of its own, which the worker's death would not reach) and no compiler's folder."""
    abandon()
    os._exit(128 + signum)


def usable_scheme(scheduler: str) -> None:
    """Refuse (InputError on ``--scheduler``) a scheduler address whose scheme this
    installation's Dask has no working communication back end for: ``ucx://`` needs the
    ``distributed-ucxx`` package (Dask's own UCX back end was removed, and connecting
    through its stub fails with an internal TypeError).  Dask must be installed."""
    from distributed.comm.registry import get_backend

    scheme = scheduler.partition("://")[0] if "://" in scheduler else "tcp"
    try:
        get_backend(scheme).get_connector()
    except Exception as exc:  # a back end missing, or a stub left where one was removed
        why = ("UCX needs the distributed-ucxx package" if scheme == "ucx"
               else f"{type(exc).__name__}: {exc}")
        raise InputError("(command line)", "--scheduler",
                         f"a scheme this installation's Dask can connect with; {scheduler}: "
                         f"{scheme}:// has no working back end here ({why})") from None


def _on_dask(fn: Callable[[T], R], items: Sequence[T],
             scheduler: str) -> Iterator[tuple[int, R]]:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError:
        raise InputError("(command line)", "--scheduler",
                         "dask.distributed installed (pip install 'cpas-ocp[cluster]')") from None
    usable_scheme(scheduler)
    try:
        client = Client(scheduler, timeout=30)
    except OSError as exc:
        raise InputError("(command line)", "--scheduler",
                         f"a reachable Dask scheduler; {scheduler}: {exc}") from None
    with client:
        futures = client.map(fn, list(items), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        for future in dask_completed(futures):
            yield index[future.key], future.result()
