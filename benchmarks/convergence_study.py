"""Study: from how far off a user's guesses does a fit still reach the best optimum?

Each built-in problem named is simulated (seed 1) and one estimator built.
Then, `--starts` times, its reduction start is perturbed as a user's guesses
would be: every inflation start time shifted by a uniform draw in +-0.3 s
and every other inflation parameter (CdS, n, n_p, expopen, Ck, t_k) scaled
by a uniform draw in 0.7-1.3, each clipped into its bounds.  The start-time
windows stay those of the manifest's events (the event times themselves are
not moved).  Every start is solved with the default settings, then restarted
where a start time misfits (`restarts`, as `cpas-ocp reconstruct` does;
`--no-restarts` for the earlier path).

A start reaches the basin when it converges to a chi-square within 1 of the
best any start found.  Printed per problem: converged starts, starts in the
basin, the spread of chi-square, iterations (median and largest, of the
first solve), wall time (with restarts) and how many fits were restarted.
Draws come from `numpy.random.default_rng(--seed)`.

    python benchmarks/convergence_study.py [--problems fbcp drogue ...] [--starts 50]
                                           [--seed 0] [--no-restarts]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
import numpy as np

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.restarts import restart_start_times
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.parameters import split_name

SHAPES = ("CdS", "n", "n_p", "expopen", "Ck", "t_k")  # inflation parameters scaled +-30 %
START_SHIFT_S = 0.3
SCALE_SPAN = 0.3
BASIN_CHI2 = 1.0


def perturbed_start(est: Estimator, rng: np.random.Generator) -> np.ndarray:
    """The reduction's decision vector with the free inflation parameters perturbed."""
    z = est.initial_point()
    offset = est.transcription.sizes[0]
    for i, name in enumerate(est.free):
        prm = est.model.parameter(name)
        base = split_name(name)[0]
        value = z[offset + i] * est.pscale[i]
        if base == "t_start":
            value += rng.uniform(-START_SHIFT_S, START_SHIFT_S)
        elif base in SHAPES:
            value *= rng.uniform(1.0 - SCALE_SPAN, 1.0 + SCALE_SPAN)
        else:
            continue
        z[offset + i] = float(np.clip(value, prm.lower, prm.upper)) / est.pscale[i]
    return z


def study(name: str, starts: int, rng: np.random.Generator, folder: Path,
          restarts: bool = True) -> dict:
    """Run and print the study of one problem; its figures."""
    simulate_problem(load_problem(name), folder, 1)
    est = Estimator(load_test(folder))
    chi2, iterations, walls, failures = [], [], [], []
    restarted = 0
    timer = harness.Timer()
    for k in range(starts):
        try:
            with timer("start"):
                fit = est.solve(start=perturbed_start(est, rng))
                if restarts:
                    fit, done = restart_start_times(est, fit)
                    restarted += bool(done)
        except SolverFailure as exc:
            walls.append(timer["start"])
            failures.append(f"{exc.status} after {exc.iterations}")
            print(f"  {name} start {k + 1:3d}: FAILED, {failures[-1]} iterations, "
                  f"{walls[-1]:6.1f} s", flush=True)
            continue
        walls.append(timer["start"])
        chi2.append(fit.chi_square)
        iterations.append(fit.solver.iterations)
        print(f"  {name} start {k + 1:3d}: chi-square {fit.chi_square:12.3f}, "
              f"{fit.solver.iterations:3d} iterations, {walls[-1]:6.1f} s", flush=True)
    if not chi2:
        print(f"{name}: no start converged ({'; '.join(failures[:3])})")
        return {"starts": starts, "converged": 0, "failures": failures}
    best = min(chi2)
    basin = sum(c - best <= BASIN_CHI2 for c in chi2)
    print(f"{name:12s} converged {len(chi2)}/{starts}, in the basin {basin}/{starts} "
          f"({100.0 * basin / starts:.0f} %), chi-square best {best:.3f} worst "
          f"{max(chi2):.3f}, iterations median {int(np.median(iterations))} max "
          f"{max(iterations)}, wall median {np.median(walls):.1f} s, restarted {restarted}"
          + (f"; failures: {'; '.join(failures[:3])}" if failures else ""), flush=True)
    return {"starts": starts, "converged": len(chi2), "in_basin": basin,
            "chi_square_best": best, "chi_square_worst": max(chi2),
            "iterations_median": int(np.median(iterations)), "iterations_max": max(iterations),
            "wall_s_median": float(np.median(walls)), "restarted": restarted,
            "failures": failures}


def main() -> None:
    parser = harness.parser(__doc__, seed=0, seed_help="seed of the starts' perturbations")
    parser.add_argument("--problems", nargs="+", default=["fbcp", "drogue", "pilot", "main2"])
    parser.add_argument("--starts", type=int, default=50)
    parser.add_argument("--no-restarts", action="store_true",
                        help="the earlier path: no restarts of misfit start times")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        problems = {name: study(name, args.starts, rng, Path(tmp) / name, not args.no_restarts)
                    for name in args.problems}
    harness.report("convergence_study", restarts=not args.no_restarts, problems=problems)


if __name__ == "__main__":
    main()
