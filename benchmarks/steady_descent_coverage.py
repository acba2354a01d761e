"""Benchmark: calibration of the drag-area sigmas of a steady descent (`rocket_steady`).

Each seed simulates the built-in `rocket_steady` problem (a rocket picked up
under its open drogue, a main deployed mid-phase, a barometric altimeter
alone) into a temporary folder and reconstructs it as a user would:
``Estimator(load_test(folder))``, ``solve()``, ``covariance(fit)``; the
simulator's truth.json is moved out of the folder first and read only for
scoring.  Per seed and drag area: z = (estimate - truth) / sigma.

If the sigmas are right, z is standard normal: the 1-sigma interval covers the
truth in 68.3 % of seeds, the 2-sigma one in 95.4 %, mean z is 0 and mean z^2
is 1 (its 95 % range over n seeds is chi2_n(0.025..0.975) / n).  Printed per
drag area: coverage of both intervals with the binomial 95 % range at n, mean
z, mean z^2 with its range, and the wall time per seed.

    python benchmarks/steady_descent_coverage.py [--seeds 20] [--first 1]
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import harness
import numpy as np
from scipy.stats import binom, chi2, norm

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

PROBLEM = "rocket_steady"


def score_seed(seed: int) -> tuple[dict[str, float], float, str]:
    """(drag area -> z, wall time (s), error text or '') of one seed."""
    timer = harness.Timer()
    with tempfile.TemporaryDirectory(prefix="cpas-steady-") as tmp:
        folder = Path(tmp) / "test"
        simulate_problem(load_problem(PROBLEM), folder, seed)
        truth_file = (folder / "truth.json").rename(Path(tmp) / "truth.json")
        est = Estimator(load_test(folder))
        try:
            fit = est.solve()
        except SolverFailure as err:
            return {}, timer.elapsed(), f"solve: {err}"
        cov = est.covariance(fit)
        truth = json.loads(truth_file.read_text())["parameters"]
    z = {n: (fit.parameters[n] - truth[n]) / cov.std[n] for n in fit.free
         if n.startswith("CdS[") and n not in cov.at_bound}
    return z, timer.elapsed(), ""


def main() -> None:
    parser = harness.parser(__doc__, seed=None, seed_help="recorded only: each seed's draws "
                            "are seeded by that seed (--first, --seeds)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first", type=int, default=1)
    args = parser.parse_args()
    seeds = range(args.first, args.first + args.seeds)
    zs: dict[str, list[float]] = {}
    walls, failures = [], []
    for seed in seeds:
        z, wall, error = score_seed(seed)
        walls.append(wall)
        if error:
            failures.append(f"seed {seed}: {error}")
        for name, value in z.items():
            zs.setdefault(name, []).append(value)
    print(f"{PROBLEM}: {args.seeds} seeds from {args.first}")
    print(f"{'drag area':22s} {'n':>3s} {'1σ cover %':>10s} {'2σ cover %':>10s} "
          f"{'mean z':>7s} {'mean z²':>8s} {'max |z|':>8s}")
    areas = {}
    for name, values in zs.items():
        z = np.array(values)
        areas[name] = {"n": z.size, "cover_1_sigma_percent": 100 * np.mean(np.abs(z) < 1),
                       "cover_2_sigma_percent": 100 * np.mean(np.abs(z) < 2),
                       "mean_z": z.mean(), "mean_z2": np.mean(z**2), "max_abs_z": np.abs(z).max()}
        print(f"{name:22s} {z.size:3d} {areas[name]['cover_1_sigma_percent']:10.1f} "
              f"{areas[name]['cover_2_sigma_percent']:10.1f} {z.mean():7.2f} "
              f"{np.mean(z**2):8.2f} {np.abs(z).max():8.2f}")
    n = max((len(v) for v in zs.values()), default=0)
    if n:
        for k in (1, 2):
            p = 1.0 - 2.0 * norm.sf(k)
            lo, hi = binom.interval(0.95, n, p)
            print(f"nominal {k}σ coverage {100 * p:.1f} %; binomial 95 % range at n = {n}: "
                  f"{100 * lo / n:.0f}-{100 * hi / n:.0f} %")
        lo, hi = chi2.interval(0.95, n)
        print(f"mean z² 95 % range at n = {n}: {lo / n:.2f}-{hi / n:.2f}; mean z 95 % range: "
              f"±{1.96 / np.sqrt(n):.2f}")
    print(f"failures: {len(failures)}" + "".join(f"\n  {f}" for f in failures))
    print(f"wall time per seed (simulate, build, solve, covariance): mean "
          f"{np.mean(walls):.1f} s, max {np.max(walls):.1f} s")
    harness.report("steady_descent_coverage", seeds=args.seeds, first=args.first,
                   drag_areas=areas, failures=failures,
                   wall_s_per_seed={"mean": np.mean(walls), "max": np.max(walls)})


if __name__ == "__main__":
    main()
