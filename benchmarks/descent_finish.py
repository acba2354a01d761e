"""The finish of a stalled run: Gauss-Newton steps halved (the earlier path) against steps
that learn the curvature Gauss-Newton leaves out, in one script.

Three configurations:

* ``before``: `Settings(descent_curvature=False, descent_steps=15)` at
  `revisions.SWITCHES`, the last revision with that switch: each failed
  trial halved, at most 15 steps;
* ``learnt, 15``: a failed trial's parabola along the feasible curve sets
  the next trial and can end the descent, and the residuals' curvature is
  learnt from the steps (`structured_secant`), at most 15 steps;
* ``after``: the defaults, the same with at most 30 steps.

Cases, each solved under each:

* for each test folder given (`cpas-ocp import-altus` of the Prometheus logs
  under the card): the card model's fit (`--still`: that model in still
  air), and from it the main's held-expopen profile as `flight` makes it
  (`flight_report.HELD_PROFILE_FACTORS`, each point given 100 iterations;
  its row gives the points that converged in place of iterations, and the
  least delta chi-square);
* `--gusts N`: `rocket_gusts` seeds 1..N (from `--seed` on) flown through their gusts and
  fitted from the reduction with the wind process they were drawn from.

Printed per case and configuration: converged or the failure, iterations,
wall time and chi-square; then per configuration how many converged, and
the wall-time ratios to `before` over the cases every path finished.  Each
case and configuration runs in a process of its own (`revisions.call_at`),
its models compiled before they run into a cache all share.

    python benchmarks/descent_finish.py [FOLDER ...] [--still] [--gusts 10] [--seed 1]
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import harness
import numpy as np
from revisions import SWITCHES, call_at, code_at

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.process_intensity import without_wind
from cpas_ocp.inference.profile_likelihood import held_profile
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_block, spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.reports.flight_report import HELD_PROFILE_FACTORS as HELD_FACTORS
from cpas_ocp.reports.flight_report import HELD_PROFILE_MAX_ITER as HELD_MAX_ITER

HELD = "expopen[main,stage2]"
# Per path: the revision (None: this tree) and its Settings.
PATHS = {"before": (SWITCHES, {"descent_curvature": False, "descent_steps": 15}),
         "learnt, 15": (None, {"descent_steps": 15}),
         "after": (None, {"descent_steps": 30})}


Outcome = tuple[bool, int, float, float]  # converged, iterations, wall s, chi-square
OUTCOME = ("converged", "iterations", "wall_s", "chi_square")


def timed(solve: Callable[[], Fit]) -> tuple[Outcome, Fit | None]:
    """The outcome of `solve`, and its fit where it converged."""
    timer = harness.Timer()
    try:
        with timer("solve"):
            fit = solve()
        return (True, fit.solver.iterations, timer["solve"], fit.chi_square), fit
    except SolverFailure as exc:
        return (False, exc.iterations, timer["solve"], float("nan")), None


def held_case(folder: str, still: bool, options: dict) -> tuple[Outcome, Outcome]:
    """With `Settings(**options)`: the card model's fit and its main's held-expopen profile
    (as `flight` makes it: walking out from the fit, each point from its neighbour)."""
    test = load_test(folder)
    spec = spec_of_test(test)
    spec = without_wind(spec, test) if still else spec
    fitted, fit = timed(Estimator(test, spec, Settings(**options)).solve)
    if fit is None:
        return fitted, (False, 0, 0.0, float("nan"))
    timer = harness.Timer()
    with timer("profile"):
        prof = held_profile(fit, spec, HELD, fit.parameters[HELD] * np.array(HELD_FACTORS),
                            max_iter=HELD_MAX_ITER)
    converged = len(HELD_FACTORS) - len(prof.failures)
    return fitted, (not prof.failures, converged, timer["profile"],
                    float(prof.delta_chi_square.min()))


def held_cases(folder: str, still: bool, cache: Path) -> dict[str, dict[str, Outcome]]:
    """`held_case` under each path."""
    name = str(folder)
    out: dict[str, dict[str, Outcome]] = {f"{name} fit": {}, f"{name} held profile": {}}
    for label, (revision, options) in PATHS.items():
        with code_at(revision) as code:
            fitted, profile = call_at(code, "descent_finish", "held_case", str(folder), still,
                                      options, cache=cache)
        out[f"{name} fit"][label] = tuple(fitted)
        out[f"{name} held profile"][label] = tuple(profile)
    return out


def gust_case(folder: str, options: dict) -> Outcome:
    """A rocket_gusts test's fit with the wind process it was drawn from, with
    `Settings(**options)`."""
    problem = load_problem("rocket_gusts")
    truth_block = problem.simulation["model"]
    block = {**problem.manifest["model"],
             "effects": [truth_block["effects"][0], *problem.manifest["model"]["effects"]]}
    spec = spec_from_block(block, "descent_finish benchmark", Path())
    return timed(Estimator(load_test(folder), spec, Settings(**options)).solve)[0]


def gust_cases(seeds: int, first: int, cache: Path) -> dict[str, dict[str, Outcome]]:
    """Each rocket_gusts seed's (`seeds` of them from `first`) fit with the wind process,
    under each path."""
    problem = load_problem("rocket_gusts")
    out: dict[str, dict[str, Outcome]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, first + seeds):
            folder = Path(tmp) / f"seed{seed}"
            simulate_problem(problem, folder, seed)
            for label, (revision, options) in PATHS.items():
                with code_at(revision) as code:
                    out.setdefault(f"rocket_gusts seed {seed}", {})[label] = tuple(call_at(
                        code, "descent_finish", "gust_case", str(folder), options, cache=cache))
            print_case(f"rocket_gusts seed {seed}", out[f"rocket_gusts seed {seed}"])
    return out


def print_case(name: str, outcomes: dict[str, Outcome]) -> None:
    cells = []
    for label, (ok, iterations, wall, chi2) in outcomes.items():
        cells.append(f"{label}: {'ok    ' if ok else 'FAILED'} {iterations:4d} it "
                     f"{wall:6.1f} s chi2 {chi2:10.2f}")
    print(f"{name:45s} " + ("\n" + " " * 46).join(cells), flush=True)


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="the first rocket_gusts seed of --gusts")
    parser.add_argument("folders", nargs="*")
    parser.add_argument("--still", action="store_true")
    parser.add_argument("--gusts", type=int, default=0)
    args = parser.parse_args()
    cases: dict[str, dict[str, Outcome]] = {}
    with tempfile.TemporaryDirectory() as cache:
        for folder in args.folders:
            held = held_cases(folder, args.still, Path(cache))
            for name, outcomes in held.items():
                print_case(name, outcomes)
            cases.update(held)
        if args.gusts:
            cases.update(gust_cases(args.gusts, args.seed, Path(cache)))
    both = [c for c in cases.values() if all(o[0] for o in c.values())]
    converged, ratios = {}, {}
    for label in PATHS:
        converged[label] = sum(c[label][0] for c in cases.values())
        print(f"{label}: {converged[label]} of {len(cases)} converged")
    if both:
        for label in list(PATHS)[1:]:
            ratios[label] = harness.ratio(sum(c[label][2] for c in both),
                                          sum(c["before"][2] for c in both))
            print(f"wall time {label}/before over the {len(both)} cases all finished: "
                  f"{ratios[label]:.2f}")
    harness.report("descent_finish", cases=len(cases), converged=converged,
                   all_finished=len(both), wall_ratio_to_before=ratios,
                   outcomes={name: {label: dict(zip(OUTCOME, o, strict=True))
                                    for label, o in c.items()} for name, c in cases.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
