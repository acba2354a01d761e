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

import argparse
import dataclasses
import functools
import resource
import tempfile
import time
from pathlib import Path

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
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        print(f"[{case}]   {time.perf_counter() - t0:7.1f} s  {label(args, out)}", flush=True)
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
    t_start = time.perf_counter()
    fit = solve_with_continuation(Estimator(load_test(folder), baseline_spec()))
    return fit, time.perf_counter() - t_start


def run(case: str, seed: int, root: Path, null_point: str = "score") -> None:
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
    try:
        t0 = time.perf_counter()
        diag = diagnosis_module.diagnose(fit, spec)
        t_diag = time.perf_counter() - t0
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hidden", nargs="+", default=["added_mass"],
                        choices=list(hidden_cases()))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--null-point", choices=["score", "solve"], default="score")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.hidden:
            run(case, args.seed, Path(tmp), args.null_point)


if __name__ == "__main__":
    main()
