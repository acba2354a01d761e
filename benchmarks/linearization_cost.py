"""Benchmark: the cost of linearising the estimation problem, function buffer against DM.

`linearize` evaluates the weighted residuals with their Jacobian and the
constraints with theirs at a point; the statistical stopping test, every
covariance, profile step and score test start from it.  Both ways of getting
the values into NumPy/SciPy are timed in this process on the same estimator
and point (the reduction's start), best of `--repeat`:

* ``dm``: the function called with a vector, its DM outputs copied out of
  Python lists (the earlier path, `evaluate(..., via_dm=True)`);
* ``buffer``: CasADi's function buffer writing into preallocated arrays on
  a pattern converted once (the default).

    python benchmarks/linearization_cost.py [--problems drogue drogue_full ...] [--repeat 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from cpas_ocp.estimation import Estimator
from cpas_ocp.flight_test import load_test
from cpas_ocp.problems import load_problem
from cpas_ocp.simulate import simulate_problem
from cpas_ocp.uncertainty import evaluate


def best(functions: tuple, z: np.ndarray, via_dm: bool, repeat: int) -> float:
    """Fastest of `repeat` evaluations of every function in `functions` at `z` (s)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for f in functions:
            evaluate(f, z, via_dm=via_dm)
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", nargs="+", default=["drogue", "drogue_full"])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"{'problem':12s} {'Jacobian nonzeros':>18s} {'dm s':>8s} {'buffer s':>9s} {'ratio':>6s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.problems:
            folder = Path(tmp) / name
            simulate_problem(load_problem(name), folder, 1)
            est = Estimator(load_test(folder))
            z = est.initial_point()
            functions = (est._residual_jacobian, est._constraints)
            old = [evaluate(f, z, via_dm=True) for f in functions]
            new = [evaluate(f, z) for f in functions]
            for a, b in zip(old, new, strict=True):  # the same numbers either way
                assert np.array_equal(a[0], b[0]) and (a[1] != b[1]).nnz == 0
            nnz = sum(out[1].nnz for out in new)
            t_dm = best(functions, z, True, args.repeat)
            t_buf = best(functions, z, False, args.repeat)
            print(f"{name:12s} {nnz:18,d} {t_dm:8.3f} {t_buf:9.3f} {t_buf / t_dm:6.2f}",
                  flush=True)


if __name__ == "__main__":
    main()
