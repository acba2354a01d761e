"""Benchmark: the forward substitution through the shooting gaps (`kkt_system.
reduce_linearisation`, every Gauss-Newton step, covariance and feasible descent takes
it) with BLAS on one thread against the pools as loaded, alone and beside a process
that keeps one core busy.

The problem is the 10-minute, 100 Hz log of `long_log.py` (barometer and
accelerometer, the rocket default model: 7,517 shooting nodes, 178 free coordinates),
imported in this process and linearised at the reduction's point.  Each side reduces
the linearisation `--repeat` times; printed per condition the median seconds of each
side and the ratio pools / one thread.  The busy process multiplies small matrices on
its own BLAS pool, as another fit or a second pytest worker does.

    python benchmarks/chain_solve_threads.py [--repeat 3] [--seed 1]
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import harness  # noqa: E402
from long_log import imported_estimator  # noqa: E402

from cpas_ocp.estimation import kkt_system  # noqa: E402

# A second process of numerical work: small products on its own BLAS pool, whose threads
# spin between them (another fit, a second pytest worker).
BUSY = "import numpy as np\na = np.ones((300, 300))\nwhile True: a @ a"


def timings(lin: kkt_system.Linearisation, repeat: int) -> dict[str, float]:
    """Median seconds of `repeat` reductions of `lin` per side."""
    out = {}
    for side, one in (("pools", False), ("one_thread", True)):
        kkt_system.CHAIN_SOLVE_ON_ONE_THREAD = one
        laps = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            kkt_system.reduce_linearisation(lin)
            laps.append(time.perf_counter() - t0)
        out[side] = statistics.median(laps)
    kkt_system.CHAIN_SOLVE_ON_ONE_THREAD = True
    return out


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the log's sensor noise")
    parser.add_argument("--repeat", type=int, default=3, help="reductions per side")
    args = parser.parse_args()
    est = imported_estimator(args.seed)
    lin = est.linearisations.linearise(est.starts.initial_point())
    print(f"{lin.z.size} variables, {lin.dependent.size} shooting states eliminated")
    results = {"alone": timings(lin, args.repeat)}
    busy = subprocess.Popen([sys.executable, "-c", BUSY])
    try:
        time.sleep(0.5)
        results["beside_blas_work"] = timings(lin, args.repeat)
    finally:
        busy.kill()
        busy.wait()
    for condition, t in results.items():
        t["ratio_pools_over_one"] = harness.ratio(t["pools"], t["one_thread"])
        print(f"{condition}: pools {t['pools']:.2f} s, one thread {t['one_thread']:.2f} s, "
              f"ratio {t['ratio_pools_over_one']:.1f}")
    harness.report("chain_solve_threads", **results)


if __name__ == "__main__":
    main()
