"""Benchmark: the first fit of the 10-minute, 100 Hz log of `long_log.py` (barometer and
accelerometer, the rocket default model; it stalls and is finished by feasible descents),
with each descent step's held reductions taken from the free one's columns
(`ReducedProblem.holding`) against a forward substitution of their own (the earlier
path, `feasible_descent.HELD_FROM_FREE_REDUCTION = False`), in one process on one
estimator.  Printed per side: wall time, status, iterations and chi-square (which must
agree), and the ratio earlier / now.

    python benchmarks/descent_reductions.py [--seed 1]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import harness  # noqa: E402
from long_log import imported_estimator  # noqa: E402

from cpas_ocp.estimation import feasible_descent  # noqa: E402


def main() -> None:
    args = harness.parser(__doc__, seed=1, seed_help="seed of the log's sensor noise") \
        .parse_args()
    est = imported_estimator(args.seed)
    results = {}
    for side, derived in (("earlier", False), ("now", True)):
        feasible_descent.HELD_FROM_FREE_REDUCTION = derived
        t0 = time.perf_counter()
        fit = est.solve()
        wall = time.perf_counter() - t0
        results[side] = {"wall_s": wall, "status": fit.solver.status,
                         "iterations": fit.solver.iterations, "chi_square": fit.chi_square}
        print(f"{side}: {wall:.1f} s, {fit.solver.status}, {fit.solver.iterations} "
              f"iterations, chi-square {fit.chi_square:.4f}", flush=True)
    feasible_descent.HELD_FROM_FREE_REDUCTION = True
    speed_up = harness.ratio(results["earlier"]["wall_s"], results["now"]["wall_s"])
    print(f"speed-up (earlier / now): {speed_up:.2f}")
    harness.report("descent_reductions", speed_up=speed_up, **results)


if __name__ == "__main__":
    main()
