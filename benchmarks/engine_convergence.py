"""Benchmark: iterations, wall time and chi-square of a fit from the reduction, old path
against new, in one script.

Each built-in problem named is simulated (seed 1 unless `--seed`) and
reconstructed from the offline reduction twice per configuration, on the
same Estimator settings but for the solver path:

* ``before``: Ipopt's default watchdog (a full step tried on trust after 10
  shortened line searches) and the statistical stop only at an iterate that
  is itself feasible (`Settings(watchdog_trigger=10, polish=False)` at
  `revisions.SWITCHES`, the last revision with that switch);
* ``after``: the defaults (watchdog after 3, and the statistical stop may end
  a nearly feasible run with one Gauss-Newton step of its own).

Each fit runs in a process of its own (`revisions.call_at`), its model
compiled before it runs into a cache both share; the solve alone is timed.
Printed per problem: iterations, solve wall time, chi-square of each, and the
ratios after/before.  Chi-square must agree to the stopping rule's 0.01 (plus
the second-order rest of a step).

    python benchmarks/engine_convergence.py [--problems drogue drogue_full ...] [--seed N]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
from revisions import SWITCHES, call_at, code_at

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

# Per path: the revision (None: this tree) and its Settings.
PATHS = {"before": (SWITCHES, {"watchdog_trigger": 10, "polish": False}), "after": (None, {})}


def solve(folder: str, options: dict) -> tuple[int, float, float, str]:
    """(iterations, solve wall s, chi-square, status) of one fit from the reduction, with
    `Settings(**options)`."""
    est = Estimator(load_test(folder), settings=Settings(**options))
    try:
        fit = est.solve()
    except SolverFailure as exc:
        return exc.iterations, float("nan"), float("nan"), exc.status
    return fit.solver.iterations, fit.solver.wall_s, fit.chi_square, fit.solver.status


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    parser.add_argument("--problems", nargs="+", default=["drogue", "drogue_full"])
    args = parser.parse_args()
    print(f"{'problem':12s} {'path':7s} {'iter':>5s} {'solve s':>8s} {'chi-square':>12s}  status")
    problems = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.problems:
            folder = Path(tmp) / name
            simulate_problem(load_problem(name), folder, args.seed)
            runs = {}
            for label, (revision, options) in PATHS.items():
                with code_at(revision) as code:
                    runs[label] = tuple(call_at(code, "engine_convergence", "solve",
                                                str(folder), options, cache=Path(tmp) / "cache"))
                it, wall, chi2, status = runs[label]
                print(f"{name:12s} {label:7s} {it:5d} {wall:8.1f} {chi2:12.3f}  {status}",
                      flush=True)
            (ib, wb, cb, _), (ia, wa, ca_, _) = runs["before"], runs["after"]
            ratios = {"iterations": harness.ratio(ia, ib), "solve_s": harness.ratio(wa, wb)}
            print(f"{name:12s} after/before: iterations {ratios['iterations']:.2f}, solve time "
                  f"{ratios['solve_s']:.2f}, chi-square difference {ca_ - cb:+.4f}", flush=True)
            problems[name] = {"runs": {label: dict(zip(("iterations", "solve_s", "chi_square",
                                                        "status"), r, strict=True))
                                       for label, r in runs.items()},
                              "after_over_before": ratios,
                              "chi_square_difference": ca_ - cb}
    harness.report("engine_convergence", problems=problems)


if __name__ == "__main__":
    main()
