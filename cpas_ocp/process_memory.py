"""Giving the memory of finished model builds back to the operating system.

Each candidate of a diagnosis builds and solves its own NLP, and CasADi's
functions allocate and free hundreds of megabytes while they are built and
evaluated (the per-interval Jacobians run in two threads, each with its own
malloc arena).  glibc keeps what is freed for reuse rather than returning it,
so the resident size of a `drogue` diagnosis grew by 120-150 MB per candidate,
to a peak of 2.1 GB, while what was live after each candidate stayed near
0.2-0.6 GB.  Trimming the heap after each candidate brings the peak to 0.84 GB
(`benchmarks/diagnosis_cost.py` prints it).

A full collection walks every object the process holds (the libraries' modules,
and in a notebook or a test run whatever else it keeps): 60 ms a candidate in a
`diagnose` command and 114 ms in a test process.  Within `new_objects_only` the
objects older than the diagnosis are frozen out of the collections (`gc.freeze`),
which then walk only what the candidates made.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import gc
from collections.abc import Iterator


@functools.cache
def _malloc_trim() -> ctypes._CFuncPtr | None:
    """glibc's malloc_trim, or None where the C library has none (macOS, musl)."""
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


def release_freed_memory() -> None:
    """Collect unreachable objects and return the freed heap to the system (glibc)."""
    gc.collect()
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


_FROZEN = [0]  # depth of `new_objects_only` blocks


@contextlib.contextmanager
def new_objects_only() -> Iterator[None]:
    """Within it, `release_freed_memory` collects only objects made after it began: those
    that existed then and were reachable are left out until it ends (nested blocks: until
    the outermost)."""
    if _FROZEN[0] == 0:
        gc.collect()  # what is garbage already is not frozen with the live objects
        gc.freeze()
    _FROZEN[0] += 1
    try:
        yield
    finally:
        _FROZEN[0] -= 1
        if _FROZEN[0] == 0:
            gc.unfreeze()
