"""The BLAS pools held to one thread, and given back."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_info

from cpas_ocp.blas_threads import one_thread


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_every_blas_pool_runs_on_one_thread_inside_and_as_before_after() -> None:
    np.ones((4, 4)) @ np.ones((4, 4))  # NumPy's BLAS loaded
    before = _blas_threads()
    assert before
    with one_thread():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before
