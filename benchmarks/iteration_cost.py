"""Benchmark: Ipopt's functions as CasADi expressions against one evaluation per point, and
Gauss-Newton against Marquardt-damped Gauss-Newton, in one script.

Per problem (simulated with seed 1 unless `--seed`) the fit from the offline
reduction is solved three ways:

* ``expressions``: the earlier path, Ipopt's objective, gradient, constraint
  Jacobian and Gauss-Newton Hessian as CasADi expressions, each evaluating
  the residuals or the Jacobians it needs (`Settings(point_cache=False)`);
* ``cached``: the same iterations, every model evaluation made once per
  point in native code and shared (`Settings(damping=False)`);
  both at `revisions.SWITCHES`, the last revision with the `damping` switch;
* ``damped``: the cached functions with Levenberg-Marquardt damping where
  Gauss-Newton steps fail to deliver;
* ``windowed``: the defaults, the damped path with Ipopt given each
  parameter's Jacobian entries only within its window of action
  (`action_windows`).

``drogue+added_mass`` is the `drogue` problem simulated with added mass
(factor 1.4 on both Drogues) and fitted without it: a misspecified model, the
case of every diagnosis and comparison.  Runs are capped at `--max-iter`
(150) iterations.  Printed: iterations, solve wall time, time per iteration,
chi-square, status, and the ratios to ``expressions``.  Each fit runs in a
process of its own (`revisions.call_at`), its model compiled before it runs
into a cache all share; the solve alone is timed.

    python benchmarks/iteration_cost.py [--problems drogue drogue_full drogue+added_mass]
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import harness
from diagnosis_cost import hidden_cases
from revisions import SWITCHES, call_at, code_at

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem

# Per path: the revision (None: this tree) and its Settings.
PATHS = {"expressions": (SWITCHES, {"point_cache": False, "damping": False}),
         "cached": (SWITCHES, {"damping": False, "window_margin": None}),
         "damped": (None, {"window_margin": None}), "windowed": (None, {})}


def make_test(name: str, seed: int, root: Path) -> str:
    """The test folder of a built-in problem, or of `drogue` with an effect hidden."""
    problem_name, _, hidden = name.partition("+")
    problem = load_problem(problem_name)
    effects = None
    if hidden:
        effects, values = hidden_cases()[hidden]
        problem = dataclasses.replace(problem, truth={**problem.truth, **values})
    simulate_problem(problem, root / name, seed, effects=effects)
    return str(root / name)


def run(folder: str, misspecified: bool, max_iter: int, options: dict
        ) -> tuple[int, float, float, str]:
    """(iterations, solve wall s, chi-square, status) of one fit from the reduction (the
    chi-square is NaN where the solve failed), with `Settings(**options)`."""
    est = Estimator(load_test(folder), baseline_spec() if misspecified else None,
                    Settings(max_iter=max_iter, **options))
    timer = harness.Timer()
    try:
        with timer("solve"):
            fit = est.solve()
    except SolverFailure as exc:  # timed all the same: the cost of not converging
        return exc.iterations, timer["solve"], float("nan"), exc.status
    return fit.solver.iterations, timer["solve"], fit.chi_square, fit.solver.status


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    parser.add_argument("--problems", nargs="+",
                        default=["drogue", "drogue_full", "drogue+added_mass"])
    parser.add_argument("--max-iter", type=int, default=150)
    args = parser.parse_args()
    print(f"{'problem':18s} {'path':11s} {'iter':>5s} {'solve s':>8s} {'s/iter':>7s} "
          f"{'chi-square':>12s}  status")
    problems = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.problems:
            folder = make_test(name, args.seed, Path(tmp))
            runs = {}
            for label, (revision, options) in PATHS.items():
                with code_at(revision) as code:
                    it, wall, chi2, status = runs[label] = tuple(call_at(
                        code, "iteration_cost", "run", folder, "+" in name, args.max_iter,
                        options, cache=Path(tmp) / "cache"))
                print(f"{name:18s} {label:11s} {it:5d} {wall:8.1f} {wall / max(it, 1):7.3f} "
                      f"{chi2:12.3f}  {status}", flush=True)
            it0, wall0, chi0, _ = runs["expressions"]
            ratios = {}
            for label in ("cached", "damped", "windowed"):
                it, wall, chi2, _ = runs[label]
                r = ratios[label] = {"iterations": harness.ratio(it, it0),
                                     "solve_s": harness.ratio(wall, wall0),
                                     "per_iteration": harness.ratio(wall / it, wall0 / it0),
                                     "chi_square_difference": chi2 - chi0}
                print(f"{name:18s} {label}/expressions: iterations {r['iterations']:.2f}, solve "
                      f"time {r['solve_s']:.2f}, time per iteration {r['per_iteration']:.2f}"
                      f", chi-square difference {chi2 - chi0:+.4f}", flush=True)
            problems[name] = {"runs": {label: dict(zip(("iterations", "solve_s", "chi_square",
                                                        "status"), r, strict=True))
                                       for label, r in runs.items()},
                              "over_expressions": ratios}
    harness.report("iteration_cost", max_iter=args.max_iter, problems=problems)


if __name__ == "__main__":
    main()
