"""Giving the memory of finished model builds back to the operating system.

Each candidate of a diagnosis builds and solves its own NLP, and CasADi's
functions allocate and free hundreds of megabytes while they are built and
evaluated (the per-interval Jacobians run in two threads, each with its own
malloc arena).  glibc keeps what is freed for reuse rather than returning it,
so the resident size of a `drogue` diagnosis grew by 120-150 MB per candidate,
to a peak of 2.1 GB, while what was live after each candidate stayed near
0.2-0.6 GB.  Trimming the heap after each candidate brings the peak to 0.84 GB
(`benchmarks/diagnosis_cost.py` prints it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import gc


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
