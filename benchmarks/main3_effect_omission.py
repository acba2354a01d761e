"""Study: on `main3_full` data, the full effect set against sets that omit an effect.

`main3_full` is the three-Main cluster (first 30 s: bag strip, two disreefs,
full-open inflation) made with elastic risers (6 Hz, zeta 0.3) and added mass
(k_A = 1).  It is reconstructed three ways, all from the same data (seed 1):

1. rigid risers with added mass (omits riser elasticity), from the offline
   reduction;
2. the full set, starting from fit 1's estimate (from the reduction alone
   Ipopt had not converged after 40 iterations: chi-square 61,000, backtracking);
3. elastic risers without added mass (omits added mass), starting from fit
   2's estimate.

For each it prints solver status, iterations, wall time, chi-square / dof
and the likelihood-ratio statistic against the full set with the chi-square
0.999 quantile for the parameters it drops; for the full set, the largest
|estimate - truth| / sigma.  Too slow for the test suite (about 10 minutes on
2 cores): `python benchmarks/main3_effect_omission.py [--seed N]`.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
from pathlib import Path

import harness
from scipy.stats import chi2

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec, spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import RigidRiser
from cpas_ocp.physics.flight_test import FlightTest

MAX_ITERATIONS = 200  # each fit that converges takes 100-140


def variant(spec: ModelSpec, replace: str, by: object | None) -> ModelSpec:
    """`spec` with the effect named `replace` swapped for `by` (or dropped)."""
    effects = [by if e.name == replace else e for e in spec.effects]
    return dataclasses.replace(spec, effects=tuple(e for e in effects if e is not None))


def run(label: str, test: FlightTest, spec: ModelSpec, guess: dict[str, float],
        timer: harness.Timer) -> tuple[Estimator, Fit | None]:
    """Fit `spec` from `guess`, its solve timed under `label` in `timer`, and print it."""
    free = spec.free_names(spec.model(test))
    est = Estimator(test, spec, Settings(max_iter=MAX_ITERATIONS,
                                         guess={k: v for k, v in guess.items() if k in free}))
    try:
        with timer(label):
            fit = est.solve(progress=True)
    except SolverFailure as exc:
        print(f"{label:34s} FAILED: {exc} ({timer[label]:.0f} s)", flush=True)
        return est, None
    print(f"{label:34s} {fit.solver.status}, {fit.solver.iterations} iterations, "
          f"{timer[label]:.0f} s, chi2/dof {fit.chi_square:.0f}/{fit.dof} = "
          f"{fit.chi_square / fit.dof:.3f}", flush=True)
    return est, fit


def main() -> None:
    ap = harness.parser(__doc__, seed=1, seed_help="seed of the simulated main3_full test")
    args = ap.parse_args()
    timer = harness.Timer()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "test"
        simulate_problem(load_problem("main3_full"), folder, args.seed)
        truth = json.loads((folder / "truth.json").read_text())["parameters"]
        test = load_test(folder)
        full_spec = spec_of_test(test)
        _, rigid = run("rigid risers + added mass", test,
                       variant(full_spec, "elastic_riser", RigidRiser()), {}, timer)
        est, full = run("full set (from the rigid fit)", test, full_spec,
                        rigid.parameters if rigid else {}, timer)
        fits = {"rigid risers + added mass": rigid, "full set (from the rigid fit)": full}
        if full is None:
            harness.report("main3_effect_omission", fits=fit_figures(fits, timer))
            return
        std = est.covariance(full).std
        worst = max(full.free, key=lambda n: abs(full.parameters[n] - truth[n]) / std[n])
        z = abs(full.parameters[worst] - truth[worst]) / std[worst]
        print(f"  full set: largest |estimate - truth| {z:.2f} sigma ({worst})")
        _, no_am = run("elastic risers, no added mass", test,
                       variant(full_spec, "added_mass", None), full.parameters, timer)
        fits["elastic risers, no added mass"] = no_am
        tests = {}
        for label, reduced in (("rigid risers + added mass", rigid),
                               ("elastic risers, no added mass", no_am)):
            if reduced is None:
                continue
            dropped = len(full.free) - len(reduced.free)
            print(f"  {label}: delta chi2 {reduced.chi_square - full.chi_square:.0f} for "
                  f"{dropped} parameters (chi2 0.999 quantile {chi2.ppf(0.999, dropped):.1f})")
            tests[label] = {"delta_chi2": reduced.chi_square - full.chi_square,
                            "dropped": dropped, "chi2_0999": chi2.ppf(0.999, dropped)}
    harness.report("main3_effect_omission", fits=fit_figures(fits, timer),
                   full_set_largest_z={"parameter": worst, "z": z}, omissions=tests)


def fit_figures(fits: dict[str, Fit | None], timer: harness.Timer) -> dict:
    """Solve time, and status, iterations and chi-square, of each fit, by `run`'s label."""
    return {label: {"wall_s": timer[label]} | ({"status": "FAILED"} if fit is None else {
        "status": fit.solver.status, "iterations": fit.solver.iterations,
        "chi_square": fit.chi_square, "dof": fit.dof}) for label, fit in fits.items()}


if __name__ == "__main__":
    main()
