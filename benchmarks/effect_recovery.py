"""Benchmark: added mass and elastic risers recovered from data made with them, and what
leaving them out costs.

Each case simulates a built-in problem with the effect(s) in the truth (added mass at
k_A = 1.4, paper Eq. 1; elastic risers as a spring-damper of the given frequency and damping
ratio), moves every observed event 0.3 s off as the suite's recovery tests do, and fits
from the offline reduction, which knows neither effect: once with the truth's effects
(recording iterations, solve time, chi-square/dof, the squared Mahalanobis distance of the
estimate from the truth with its degrees of freedom, and each effect parameter with its
sigma against the truth) and once with the baseline model (rigid risers, no added mass),
whose excess chi-square is the likelihood-ratio statistic for the effect's parameters.

    python benchmarks/effect_recovery.py [--cases fbcp:added_mass:1 drogue:added_mass:4 ...]
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy.stats import chi2  # noqa: E402

from benchmarks import harness  # noqa: E402
from cpas_ocp.errors import SolverFailure  # noqa: E402
from cpas_ocp.estimation.estimator import Estimator  # noqa: E402
from cpas_ocp.estimation.simulate import simulate_problem  # noqa: E402
from cpas_ocp.io.flight_test import load_test  # noqa: E402
from cpas_ocp.io.problems import load_problem  # noqa: E402
from cpas_ocp.physics.effects import AddedMass, ElasticRiser, baseline_effects  # noqa: E402
from cpas_ocp.physics.effects.base import Effect  # noqa: E402
from cpas_ocp.physics.parameters import param_name  # noqa: E402
from cpas_ocp.precision import with_sigma  # noqa: E402
from tests.conftest import START_GUESS_OFFSET_S, offset_events  # noqa: E402

K_A = 1.4  # added-mass factor of the truth
# the truth's kind: (added mass?, the riser's (frequency Hz, damping ratio) or None for rigid)
KINDS = {"added_mass": (True, None), "elastic_riser_15hz": (False, (15.0, 0.25)),
         "elastic_riser_8hz+added_mass": (True, (8.0, 0.25))}
CASES = ["fbcp:added_mass:1", "fbcp:added_mass:2", "fbcp:added_mass:3",
         "drogue:added_mass:4", "drogue:added_mass:5", "drogue:added_mass:6",
         "fbcp:elastic_riser_15hz:1", "fbcp:elastic_riser_15hz:2",
         "drogue:elastic_riser_8hz+added_mass:1"]


def effects_of(added_mass: bool, riser: tuple[float, float] | None) -> list[Effect]:
    """The baseline effects with the riser made elastic and added mass added, as asked."""
    effects = [ElasticRiser(*riser) if riser and e.name == "rigid_riser" else e
               for e in baseline_effects()]
    return effects + ([AddedMass()] if added_mass else [])


def run_case(case: str, work: Path) -> dict:
    """Simulate, fit with and without the effects, and score the fit against the truth."""
    problem_name, kind, seed = case.split(":")
    added_mass, riser = KINDS[kind]
    problem = load_problem(problem_name)
    effects = effects_of(added_mass, riser)
    truth = dict(problem.truth)
    for c in problem.manifest["parachutes"]:
        if added_mass:
            truth[param_name("added_mass_factor", c["name"])] = K_A
        if riser:
            truth[param_name("riser_period", c["name"])] = 1.0 / riser[0]
            truth[param_name("riser_damping_ratio", c["name"])] = riser[1]
    simulate_problem(dataclasses.replace(problem, truth=truth), work / "sim", int(seed),
                     effects=effects)
    test = load_test(offset_events(work / "sim", work / "test", START_GUESS_OFFSET_S))
    timer = harness.Timer()
    row: dict = {"problem": problem_name, "truth": kind, "seed": int(seed)}
    try:
        with timer("fit"):
            est = Estimator(test, effects)
            fit = est.solve()
        cov = est.covariance(fit)
    except SolverFailure as exc:
        return row | {"status": f"{exc.status} after {exc.iterations} iterations"}
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    baseline = baseline_effects()
    added = [n for e in effects if e not in baseline for n in
             (q.name for q in e.parameters(test)) if n in fit.free]  # the effects' own
    row |= {"status": fit.solver.status, "iterations": fit.solver.iterations,
            "fit_s": timer["fit"], "chi2_dof": fit.chi_square / fit.dof,
            "mahalanobis2": m2, "dof": dof, "p": float(chi2.sf(m2, dof)),
            "effect_parameters": ", ".join(
                f"{n} {with_sigma(fit.parameters[n], cov.std[n])} ({truth[n]:.4g})"
                for n in added)}
    try:
        without = Estimator(test).solve()
    except SolverFailure as exc:
        return row | {"without": f"{exc.status} after {exc.iterations} iterations"}
    delta = without.chi_square - fit.chi_square
    row |= {"without_chi2_dof": without.chi_square / without.dof,
            "without_delta_chi2": delta, "without_dropped": len(added),
            "without_rejected_at_0_999": bool(delta > chi2.ppf(0.999, len(added)))}
    return row


def main() -> int:
    parser = harness.parser(__doc__, seed=None, seed_help="recorded only: each case names "
                            "its seed (PROBLEM:KIND:SEED)")
    parser.add_argument("--cases", nargs="+", default=CASES,
                        help=f"PROBLEM:KIND:SEED, KIND one of {', '.join(KINDS)}")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-effects-") as tmp:
        for case in args.cases:
            row = run_case(case, Path(tmp) / case.replace(":", "_").replace("+", "_"))
            rows.append(row)
            print(row, flush=True)
    harness.report("effect_recovery", cases=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
