"""The process's BLAS and OpenMP thread pools, and holding them to one thread.

OpenBLAS starts a pool of one thread per core in every process that loads it, and its
threads wait for work by spinning.  Where the work is many small products (a sparse
triangular solve's supernodes, L-BFGS-B's vector operations) the pool gains nothing,
and where another process holds a core a product waits for a spinning thread's time
slice: beside a process doing BLAS work of its own on 2 cores, the shooting chain's
solve of a 10-minute log took 96 s on a pool of two threads, 0.57 s on one (0.54 s
against 0.37 s alone; `benchmarks/chain_solve_threads.py`).
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from functools import cache

from threadpoolctl import ThreadpoolController


@cache
def pools() -> ThreadpoolController:
    """The process's BLAS and OpenMP pools, found once: `threadpool_limits` looks them up
    at every call, a third of a grouping test's 124 fits of a small campaign (1.10 s
    against 0.73 s, `benchmarks/population_cost.py`)."""
    return ThreadpoolController()


def one_thread() -> AbstractContextManager:
    """A context in which every BLAS and OpenMP pool of the process runs on one thread."""
    return pools().limit(limits=1)
