"""Benchmark: restarts of misfit start times, screened by Gauss-Newton steps against every
move solved, in the same process.

Two cases, each simulated with seed 1 unless `--seed`:

* ``pilot-late``: the `pilot` problem fitted from the reduction, then again
  from that fit with the Pilot's start time 0.2 s late, which converges to a
  second, worse minimum; the restarts should find the first again;
* ``drogue+added_mass``: the `drogue` problem flown with added mass (factor
  1.4) and fitted without it, so that four start times misfit and every move
  is tried, with nothing better to find: the restarts' cost on a
  misspecified model, the case of every diagnosis.

Per case and path (``screened``: the default; ``solved``: every move solved
to convergence) it prints the start times restarted, chi-square before and
after, and wall time, then the ratio screened / solved.

    python benchmarks/restart_cost.py [--seed N]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
from iteration_cost import make_test

from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.restarts import misfit_start_times, restart_start_times
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem

PILOT_START = "t_start[pilot1,stage1]"


def pilot_late(root: Path, seed: int) -> tuple[Estimator, Fit]:
    simulate_problem(load_problem("pilot"), root / "pilot", seed)
    est = Estimator(load_test(root / "pilot"))
    fit = est.solve()
    late = est.solve(start=est.with_value(fit.z, PILOT_START, fit.parameters[PILOT_START] + 0.2))
    print(f"[pilot-late] fit from the reduction: chi-square {fit.chi_square:.2f}; started "
          f"0.2 s late: {late.chi_square:.2f}", flush=True)
    return est, late


def drogue_added_mass(root: Path, seed: int) -> tuple[Estimator, Fit]:
    est = Estimator(make_test("drogue+added_mass", seed, root), baseline_spec())
    timer = harness.Timer()
    with timer("fit"):
        fit = est.solve()
    print(f"[drogue+added_mass] fit from the reduction: chi-square {fit.chi_square:.2f}, "
          f"{timer['fit']:.1f} s", flush=True)
    return est, fit


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    args = parser.parse_args()
    cases = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, make in (("pilot-late", pilot_late), ("drogue+added_mass", drogue_added_mass)):
            est, fit = make(Path(tmp), args.seed)
            misfit = misfit_start_times(fit)
            print(f"[{label}] misfit start times: {', '.join(misfit) or 'none'}")
            timer, paths = harness.Timer(), {}
            for path, screen in (("screened", True), ("solved", False)):
                with timer(path):
                    out, done = restart_start_times(est, fit, screen=screen)
                walls = timer.seconds()
                paths[path] = {"wall_s": walls[path], "chi_square": out.chi_square,
                               "restarts": [str(r) for r in done]}
                print(f"[{label}] {path:8s} {walls[path]:7.1f} s, chi-square {fit.chi_square:.2f}"
                      f" -> {out.chi_square:.2f}; "
                      + ("; ".join(str(r) for r in done) or "no restart replaced the fit"),
                      flush=True)
            ratio = harness.ratio(walls["screened"], walls["solved"])
            print(f"[{label}] wall screened / solved: {ratio:.3f}")
            cases[label] = {"misfit_start_times": misfit,
                            "chi_square_before": fit.chi_square, "paths": paths,
                            "screened_over_solved": ratio}
    harness.report("restart_cost", cases=cases)


if __name__ == "__main__":
    main()
