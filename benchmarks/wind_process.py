"""Air motion: the reconstruction in still air against the one with the wind process.

For each seed (`--seeds` of them, from `--seed` on), `drogue` is flown through gusts
drawn from the wind process
(`--sigma-vertical`, horizontal twice that, tau 5 s, knots every second), or
`--problem rocket_gusts` through its own (vertical 1 m/s, tau 10 s, knots
every 2 s), and reconstructed twice: with the still-air model (the
manifest's) and with `wind_process` added (the same prior the gusts were
drawn from).  Printed per
seed: chi-square/dof, the largest |z| of the drag areas and start times
against the truth, and the wall times; then, over all seeds, how often the
95 % intervals (estimate +- 1.96 sigma) of the drag areas and start times
cover the truth, for both models.  `--still` flies the seeds in still air
instead (the null check: the process should cost little there).

With `--flight FOLDER ...`, test folders imported from real logs
(`cpas-ocp import-altus`) are also fitted with and without a vertical wind
process (`--knot-s`, `--tau-s`, `--flight-sigma`), their model block taken
from the manifest.

    python benchmarks/wind_process.py [--problem drogue|rocket_gusts] [--seeds 10]
                                      [--sigma-vertical 0.5] [--still]
                                      [--flight DIR ...] [--seed 1]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import harness
import numpy as np

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec, spec_from_block, spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects.registry import BASELINE

Z95 = 1.959964


def fitted(test, spec: ModelSpec | None) -> tuple:
    """The fit of `test` with `spec` (`solve_checked`), its covariance and its wall time."""
    timer = harness.Timer()
    with timer("fit"):
        est, fit, _ = solve_checked(Estimator(test, spec))
        cov = est.covariance(fit)
    return fit, cov, timer["fit"]


def coverage_rows(fit, cov, truth: dict) -> list[tuple[str, float]]:
    """(name, |z|) of every drag area and start time with a sigma."""
    std = cov.std
    return [(n, abs(fit.parameters[n] - truth[n]) / std[n]) for n in fit.free
            if n.split("[")[0] in ("CdS", "t_start") and std.get(n)]


def simulated(args: argparse.Namespace) -> dict:
    """Fly and fit the seeds; print each and the pooled coverage, and return it."""
    problem = load_problem(args.problem)
    if args.problem == "drogue":  # the gusts are added to the built-in Drogue test
        sigma = args.sigma_vertical
        wind_block = {"effects": [{"effect": "wind_process", "sigma_vertical": sigma,
                                   "sigma_horizontal": 2.0 * sigma}, *BASELINE]}
        if not args.still:
            problem = dataclasses.replace(problem, simulation={
                **problem.simulation, "model": wind_block, "drawn": ["wind_process"]})
    else:  # a problem flown through its own gusts: fitted with the process they came from
        truth_block = problem.simulation["model"]
        wind_block = {**problem.manifest["model"],
                      "effects": [truth_block["effects"][0], *problem.manifest["model"]["effects"]]}
        if args.still:
            problem = dataclasses.replace(problem, simulation={
                **problem.simulation, "drawn": [],
                "model": {"effects": truth_block["effects"][1:]}})
    spec = spec_from_block(wind_block, "wind_process benchmark", Path())
    pooled: dict[str, list[float]] = {"still air": [], "wind process": []}
    print(f"{args.problem} {'in still air' if args.still else 'through gusts'}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seed, args.seed + args.seeds):
            folder = Path(tmp) / f"seed{seed}"
            simulate_problem(problem, folder, seed)
            truth = json.loads((folder / "truth.json").read_text())["parameters"]
            test = load_test(folder)
            line = [f"  seed {seed:2d}"]
            for label, model in (("still air", None), ("wind process", spec)):
                try:
                    fit, cov, wall = fitted(test, model)
                except SolverFailure as exc:
                    line.append(f"{label}: failed ({exc.status})")
                    continue
                rows = coverage_rows(fit, cov, truth)
                pooled[label] += [z for _, z in rows]
                line.append(f"{label}: chi2/dof {fit.chi_square / fit.dof:5.2f}, max |z| "
                            f"{max(z for _, z in rows):5.1f}, {wall:5.1f} s")
            print("  ".join(line), flush=True)
    coverage = {}
    for label, zs in pooled.items():
        z = np.array(zs)
        if z.size:
            coverage[label] = {"cover_95_percent": 100.0 * np.mean(z <= Z95),
                               "intervals": z.size, "mean_z2": np.mean(z**2)}
            print(f"{label}: 95 % intervals of drag areas and start times cover the truth "
                  f"{100.0 * np.mean(z <= Z95):.1f} % ({z.size} intervals); "
                  f"mean z^2 {np.mean(z**2):.2f}")
    return coverage


def flights(args: argparse.Namespace) -> dict:
    """Fit each flight folder with and without the vertical wind process; print and return
    each fit's figures."""
    out: dict[str, dict] = {}
    for folder in args.flight:
        test = load_test(folder)
        base = spec_of_test(test)
        wind = dataclasses.replace(base, effects=(
            spec_from_block({"effects": [{"effect": "wind_process", "components": ["up"],
                                          "knot_s": args.knot_s, "tau_s": args.tau_s,
                                          "sigma_vertical": args.flight_sigma}]},
                            "benchmark", Path()).effects[0], *base.effects))
        for label, spec in (("still air", base), ("wind process", wind)):
            try:
                fit, cov, wall = fitted(test, spec)
            except SolverFailure as exc:
                print(f"{folder} {label}: failed ({exc.status}, {exc.iterations} iterations)")
                out.setdefault(folder, {})[label] = {"failed": exc.status}
                continue
            cds = ", ".join(f"{n} {fit.parameters[n]:.4g} ± {cov.std.get(n, np.nan):.2g}"
                            for n in fit.free if n.startswith("CdS"))
            print(f"{folder} {label}: chi2/dof {fit.chi_square / fit.dof:.2f}, {cds}, "
                  f"{wall:.1f} s, {fit.solver.status}", flush=True)
            out.setdefault(folder, {})[label] = {
                "chi2_dof": fit.chi_square / fit.dof, "wall_s": wall,
                "status": fit.solver.status,
                "cds": {n: [fit.parameters[n], cov.std.get(n)] for n in fit.free
                        if n.startswith("CdS")}}
    return out


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="the first seed")
    parser.add_argument("--problem", default="drogue", choices=["drogue", "rocket_gusts"])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--sigma-vertical", type=float, default=0.5)
    parser.add_argument("--still", action="store_true")
    parser.add_argument("--flight", nargs="*", default=[])
    parser.add_argument("--knot-s", type=float, default=4.0)
    parser.add_argument("--tau-s", type=float, default=20.0)
    parser.add_argument("--flight-sigma", type=float, default=1.0)
    args = parser.parse_args()
    results = {}
    if args.seeds:
        results["coverage"] = simulated(args)
    if args.flight:
        results["flights"] = flights(args)
    harness.report("wind_process", problem=args.problem, seeds=args.seeds, still=args.still,
                   **results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
