"""Benchmark: the diagnosis of a `drogue` test with one effect hidden, step by step.

The `drogue` problem (20 s, two Drogues, three stages, GPS + IMU + two load
cells) is simulated (seed 1 unless `--seed`) with one library effect the
baseline model lacks, fitted with the baseline model from the offline
reduction, and diagnosed.  Printed: the baseline fit's iterations and time,
then per candidate effect its score test (wall time, whether its null point
needed a solve and whether that converged) and per confirming refit its
iterations, status and time; the verdict; the total wall time, the peak
resident memory of the process and of its largest compiler, and the native
builds the diagnosis started (model structures with a library to compile;
`CPAS_OCP_CACHE` pointing at an empty folder shows a first run's).

    python benchmarks/diagnosis_cost.py [--hidden added_mass elastic_riser ...] [--seed N]
                                        [--null-point score|solve]

`--null-point solve` re-solves the null point of an effect with states before
its score test (the earlier path) instead of taking the C(alpha) step.

Hidden effects: added_mass (factor 1.4 on both Drogues), elastic_riser
(6 Hz, damping 0.3), loadcell_friction (15 % loss), gps_lag (0.1 s), none.
"""

from __future__ import annotations

import dataclasses
import functools
import resource
import tempfile
from pathlib import Path

import harness

from cpas_ocp.discrepancy import diagnosis as diagnosis_module
from cpas_ocp.discrepancy import score_test as score_module
from cpas_ocp.estimation.compiled import COUNTS
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.continuation import solve as solve_with_continuation
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import (
    AddedMass,
    Effect,
    LoadCellFriction,
    SensorLag,
    baseline_effects,
    with_elastic_risers,
)

DROGUES = ("drogue1", "drogue2")


def hidden_cases() -> dict[str, tuple[list[Effect], dict[str, float]]]:
    """Truth model and the hidden effect's true values, per case."""
    base = baseline_effects()
    return {
        "none": (base, {}),
        "added_mass": ([*base, AddedMass()], {f"added_mass_factor[{c}]": 1.4 for c in DROGUES}),
        "elastic_riser": (with_elastic_risers(base),
                          {**{f"riser_period[{c}]": 1.0 / 6.0 for c in DROGUES},
                           **{f"riser_damping_ratio[{c}]": 0.3 for c in DROGUES}}),
        "loadcell_friction": ([*base, LoadCellFriction()],
                              {f"friction_loss[{c}]": 0.15 for c in DROGUES}),
        "gps_lag": ([*base, SensorLag.gps()], {"lag[gps]": 0.1}),
    }


def _timed(fn, case: str, label):
    """`fn`, printing its wall time and `label(args, out)` as each call ends."""
    def wrapper(*args, **kwargs):
        timer = harness.Timer()
        with timer("call"):
            out = fn(*args, **kwargs)
        print(f"[{case}]   {timer['call']:7.1f} s  {label(args, out)}", flush=True)
        return out
    return wrapper


def simulated_fit(effects: list[Effect], values: dict[str, float], seed: int, folder: Path
                  ) -> tuple[Fit, float]:
    """`drogue` simulated into `folder` with `effects` and the true `values` added, and the
    baseline model's fit from the offline reduction, with its wall time (s)."""
    problem = load_problem("drogue")
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **values}),
                     folder, seed, effects=effects)
    (folder / "truth.json").unlink()
    timer = harness.Timer()
    with timer("fit"):
        fit = solve_with_continuation(Estimator(load_test(folder), baseline_spec()))
    return fit, timer["fit"]


def run(case: str, seed: int, root: Path, null_point: str = "score") -> dict:
    """Fit and diagnose one case, printing each step; the figures it ends with."""
    effects, values = hidden_cases()[case]
    spec = baseline_spec()
    fit, t_fit = simulated_fit(effects, values, seed, root / case)
    print(f"[{case}] baseline fit: {fit.solver.iterations} iterations, {t_fit:.1f} s, "
          f"chi-square {fit.chi_square:.1f} ({fit.dof} dof)", flush=True)
    original_test, original_confirm = score_module.score_test, score_module.confirm
    score_module.score_test = _timed(
        functools.partial(original_test, null_point=null_point), case,
        lambda a, out: f"score {out.effect:18s} {out.note or 'null point reproduced'}")
    score_module.confirm = _timed(
        original_confirm, case,
        lambda a, out: f"refit {a[1].effect:18s} {a[1].refit_note}")
    diagnosis_module.confirm = score_module.confirm
    builds_before, libraries_before = COUNTS["builds"], COUNTS["libraries"]
    timer = harness.Timer()
    try:
        with timer("diagnosis"):
            diag = diagnosis_module.diagnose(fit, spec)
        t_diag = timer["diagnosis"]
    finally:
        score_module.score_test, score_module.confirm = original_test, original_confirm
        diagnosis_module.confirm = original_confirm
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    compiler_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
    print(f"[{case}] verdict: {diag.verdict()}")
    print(f"[{case}] diagnosis {t_diag:.1f} s, fit + diagnosis {t_fit + t_diag:.1f} s, "
          f"peak memory of the process so far {peak_gb:.2f} GB (largest compiler "
          f"{compiler_gb:.2f} GB); native builds {COUNTS['builds'] - builds_before} "
          f"({COUNTS['libraries'] - libraries_before} libraries compiled)", flush=True)
    return {"fit_iterations": fit.solver.iterations, "fit_s": t_fit,
            "chi_square": fit.chi_square, "dof": fit.dof, "verdict": diag.verdict(),
            "diagnosis_s": t_diag, "peak_gb": peak_gb, "compiler_peak_gb": compiler_gb,
            "native_builds": COUNTS["builds"] - builds_before,
            "libraries_compiled": COUNTS["libraries"] - libraries_before}


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue test")
    parser.add_argument("--hidden", nargs="+", default=["added_mass"],
                        choices=list(hidden_cases()))
    parser.add_argument("--null-point", choices=["score", "solve"], default="score")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cases = {case: run(case, args.seed, Path(tmp), args.null_point) for case in args.hidden}
    harness.report("diagnosis_cost", null_point=args.null_point, cases=cases)


if __name__ == "__main__":
    main()
