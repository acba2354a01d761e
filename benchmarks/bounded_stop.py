"""The statistical stop made from a bound the Gauss-Newton step would cross at once, against
the step that knows no bounds (`gauss_newton.bound_reached`, `measured_decrement`).

Ipopt keeps a parameter a little inside a bound the data push it against (its
barrier); a Gauss-Newton step that knows no bounds promises the decrease beyond it,
so the statistical test never ends the run there and Ipopt creeps towards the bound.
Each case is fitted from its reduction (`Estimator.solve`) with the package of
revision REV (default `BEFORE`, the last without the held step) and with this tree's,
each in a process of its own, after an untimed fit that compiles the models
both use into one cache (`revisions.call_at`).  It prints iterations, chi-square,
how the run ended and the wall time of each, and the ratio of wall times now/REV.

Cases: the three recorder layouts of the suite's synthetic rocket flight
(`tests/io/test_rocket_log_import.py`: an Altus Metrum CSV, a CATS export, a
column-mapped CSV), the two public rocket logs in `../shared/data/rocketpy-logs`
where present (each imported with its built-in card), and `drogue` and `fbcp`
simulated with `--seed`.

    python benchmarks/bounded_stop.py [--against REV] [--seed 1]
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

import harness
from revisions import ROOT, compare_cases

BEFORE = "3392e82"
SHARED = ROOT.parent / "shared" / "data" / "rocketpy-logs"
LOGS = {"ndrt_2020": "ndrt-2020/ndrt_2020_flight_data.csv",
        "genesis_2023": "genesis-2023/flight_data_faraday.csv"}


def fitted(folder: str) -> dict:
    """The fit of `folder`'s declared model from its reduction: iterations, chi-square, how
    the run ended and its wall time (for `call_at`)."""
    from cpas_ocp.errors import SolverFailure
    from cpas_ocp.estimation.estimator import Estimator
    from cpas_ocp.io.flight_test import load_test

    timer = harness.Timer()
    with timer("fit"):
        est = Estimator(load_test(Path(folder)))
        try:
            fit = est.solve()
        except SolverFailure as exc:
            return {"iterations": exc.iterations, "chi_square": float("nan"),
                    "status": exc.status, "wall_s": timer.elapsed()}
    return {"iterations": fit.solver.iterations, "chi_square": fit.chi_square,
            "status": fit.solver.status, "wall_s": timer["fit"]}


def cases(root: Path, seed: int) -> dict[str, Path]:
    """The folders fitted, by name."""
    from cpas_ocp.estimation.simulate import simulate_problem
    from cpas_ocp.io.problems import load_problem

    out = imported_logs(root)
    for problem in ("drogue", "fbcp"):
        simulate_problem(load_problem(problem), root / problem, seed)
        out[f"{problem} seed {seed}"] = root / problem
    return out


def imported_logs(root: Path) -> dict[str, Path]:
    """The synthetic rocket flight imported from each of its three recorder layouts, and the
    public rocket logs present, each imported into a folder under `root`, by name."""
    from cpas_ocp.cli import main

    sys.path.insert(0, str(ROOT))
    from tests.io import test_rocket_log_import as flights

    out: dict[str, Path] = {}
    flight = flights.fly()
    with contextlib.redirect_stdout(io.StringIO()):
        for layout in ("altus", "cats", "columns"):
            (root / layout).mkdir()
            out[f"{layout} import"] = flights._import_layout(layout, flight, root / layout)
        for card, log in LOGS.items():
            if (SHARED / log).is_file():
                assert main(["import", str(SHARED / log), "--card", card, "--out",
                             str(root / card)]) == 0
                out[card] = root / card
    return out


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated problems")
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    args = parser.parse_args()
    compare_cases("bounded_stop", "fitted", lambda root: cases(root, args.seed), args.against,
                  lambda r: f"{r['iterations']:4d} it, chi2 {r['chi_square']:12.4f}, "
                            f"{r['status']}, {r['wall_s']:5.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
