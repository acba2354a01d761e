"""Benchmark: the shooting grid chosen from the dynamics against the uniform sensor-rate grid,
in the same process.

Per case, the fit from the offline reduction is built and solved twice:

* ``uniform``: one interval per sample of the fastest sensor
  (`Settings(grid_step=default_grid_step(test))`, the earlier default);
* ``dynamics``: the default, `shooting_grid.dynamics_grid`.

Cases are built-in problems (simulated with seed 1 unless `--seed`) and, where
`../shared/data/prometheus-2022` is present (`--data`), the two Prometheus
rocket logs imported as the `flight` command imports them.  Printed per grid:
nodes, build and solve wall time, iterations, chi-square; then the ratios and
the largest parameter difference in the uniform fit's standard deviations.

    python benchmarks/shooting_grid_cost.py [--cases drogue main2 fbcp prometheus]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings, default_grid_step
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.altus_metrum import read_altus_log
from cpas_ocp.io.flight_card import load_card
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.flight_test import FlightTest


def cases(names: list[str], seed: int, data: Path, root: Path) -> dict[str, FlightTest]:
    """The test of every case that can be made here (a missing log is reported, skipped)."""
    out = {}
    for name in names:
        if name != "prometheus":
            simulate_problem(load_problem(name), root / name, seed)
            out[name] = load_test(root / name)
            continue
        card = load_card("prometheus")
        for log in card.logs:
            if not (data / log).is_file():
                print(f"{log}: not found under {data}; skipped")
                continue
            folder = root / Path(log).stem
            import_flight(read_altus_log(data / log), card, folder)
            out[Path(log).stem] = load_test(folder)
    return out


def run(test: FlightTest, settings: Settings) -> tuple[Estimator, Fit | None, float, float]:
    """(estimator, fit or None where the solve failed, build s, solve s)."""
    timer = harness.Timer()
    with timer("build"):
        est = Estimator(test, settings=settings)
    try:
        with timer("solve"):
            fit = est.solve()
    except SolverFailure as exc:
        print(f"  solve failed: {exc}")
        fit = None
    return est, fit, timer["build"], timer["solve"]


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    parser.add_argument("--cases", nargs="+", default=["drogue", "main2", "fbcp", "prometheus"])
    parser.add_argument("--data", type=Path, default=Path("../shared/data/prometheus-2022"))
    args = parser.parse_args()
    print(f"{'case':36s} {'grid':9s} {'nodes':>6s} {'build s':>8s} {'solve s':>8s} "
          f"{'iter':>5s} {'chi-square':>12s}")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, test in cases(args.cases, args.seed, args.data, Path(tmp)).items():
            runs = {}
            for label, settings in (("uniform", Settings(grid_step=default_grid_step(test))),
                                    ("dynamics", Settings())):
                est, fit, build, solve = runs[label] = run(test, settings)
                chi2 = f"{fit.chi_square:12.3f}" if fit else f"{'failed':>12s}"
                iters = fit.solver.iterations if fit else 0
                print(f"{name:36s} {label:9s} {len(est.t):6d} {build:8.1f} {solve:8.1f} "
                      f"{iters:5d} {chi2}", flush=True)
            (est_u, fit_u, build_u, solve_u), (est_d, fit_d, build_d, solve_d) = runs.values()
            out = results[name] = {
                "grids": {label: {"nodes": len(e.t), "build_s": b, "solve_s": s,
                                  "iterations": f.solver.iterations if f else None,
                                  "chi_square": f.chi_square if f else None}
                          for label, (e, f, b, s) in runs.items()},
                "dynamics_over_uniform": {"nodes": harness.ratio(len(est_d.t), len(est_u.t)),
                                          "build": harness.ratio(build_d, build_u),
                                          "solve": harness.ratio(solve_d, solve_u)}}
            r = out["dynamics_over_uniform"]
            line = (f"{name:36s} dynamics/uniform: nodes {r['nodes']:.2f}, "
                    f"build {r['build']:.2f}, solve {r['solve']:.2f}")
            if fit_u is not None and fit_d is not None:
                std = est_u.covariance(fit_u).std
                shift = max(abs(fit_d.parameters[n] - fit_u.parameters[n]) / std[n]
                            for n in fit_u.free if std.get(n, 0.0) > 0.0)
                out["chi_square_difference"] = fit_d.chi_square - fit_u.chi_square
                out["largest_parameter_difference_sigma"] = shift
                line += (f", chi-square difference {fit_d.chi_square - fit_u.chi_square:+.4f}, "
                         f"largest parameter difference {shift:.3f} sigma")
            print(line, flush=True)
    harness.report("shooting_grid_cost", cases=results)


if __name__ == "__main__":
    main()
