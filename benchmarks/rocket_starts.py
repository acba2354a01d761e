"""Benchmark: the default fit of rocket descents from the offline reduction, this tree against
an earlier revision: where the reduction starts each opening's shape, and whether and
how fast the fit converges.

Cases: the built-in `rocket_steady` and `rocket_gusts` problems (seeds 1 and 2),
the synthetic 20 Hz altimeter-only log of `tests/rocket_logs.py` (drogue
at apogee, the air's vertical motion, the altimeter's bias and lag estimated),
and, where the shared data folder holds them, the Prometheus logs imported
under their built-in card.  Each case is imported or simulated once per tree
and reconstructed as `api.reconstruct` does (`solve_checked`), in a fresh
process per tree (`revisions.run_child`).  Printed per case and tree: the
initial fill constants and shape exponents, the solver's status, its
iterations, chi-square per degree of freedom and the wall time.

    python benchmarks/rocket_starts.py [--baseline REV] [--cases NAME ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import harness  # noqa: E402
from benchmarks.revisions import code_at, run_child  # noqa: E402

BASELINE = "bac75cc"
PROMETHEUS = ROOT.parent / "shared" / "data" / "prometheus-2022"
CASES = ["rocket_steady:1", "rocket_steady:2", "rocket_gusts:1", "rocket_gusts:2",
         "altimeter_20hz:5", "prometheus:telemega-serial-6583-flight-0003.csv",
         "prometheus:telemetrum-serial-5115-flight-0001.csv"]

# argv: case, work folder, this repository's root.  Prints one JSON line.
CHILD = r"""
import json, sys, time
from pathlib import Path
case, work, root = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
import cpas_ocp  # the code tree's, before this repository's root goes on the path (tests)
sys.path.append(root)
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.io.flight_test import load_test
name, arg = case.split(":")
if name == "prometheus":
    from cpas_ocp.io.altus_metrum import read_altus_log
    from cpas_ocp.io.flight_log import import_flight
    from cpas_ocp.io.flight_card import load_card
    import_flight(read_altus_log(Path(root).parent / "shared" / "data" / "prometheus-2022"
                                 / arg), load_card("prometheus"), work / "test")
    test = load_test(work / "test")
elif name == "altimeter_20hz":
    from tests.rocket_logs import altimeter_log
    work.mkdir(parents=True, exist_ok=True)
    test = load_test(altimeter_log(work, 20.0, int(arg)))
else:
    from cpas_ocp.estimation.simulate import simulate_problem
    from cpas_ocp.io.problems import load_problem
    test = simulate_problem(load_problem(name), work / "test", int(arg))
t0 = time.perf_counter()
est = Estimator(test)
start = {k: v for k, v in est.guess.items() if k.split("[")[0] in ("n", "expopen")
         and k in est.free}
try:
    est, fit, _ = solve_checked(est)
    out = {"status": fit.solver.status, "iterations": fit.solver.iterations,
           "chi2_dof": fit.chi_square / fit.dof, "how": fit.solver.start}
except SolverFailure as exc:
    out = {"status": exc.status, "iterations": exc.iterations, "chi2_dof": float("nan"),
           "how": ""}
out.update(start=start, seconds=time.perf_counter() - t0)
print(json.dumps(out))
"""


def main() -> None:
    parser = harness.parser(__doc__, seed=None, seed_help="recorded only: each case names its "
                            "seed (NAME:SEED)")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--cases", nargs="+", default=CASES)
    parser.add_argument("--trees", nargs="+", default=["this", "baseline"],
                        choices=["this", "baseline"], help="which trees to run")
    args = parser.parse_args()
    import tempfile
    cases = [c for c in args.cases
             if not c.startswith("prometheus") or (PROMETHEUS / c.split(":")[1]).is_file()]
    trees = {"this": ("this tree", None), "baseline": (f"baseline {args.baseline}",
                                                      args.baseline)}
    results: dict[str, dict] = {}
    for label, revision in (trees[name] for name in args.trees):
        with code_at(revision) as code, tempfile.TemporaryDirectory() as tmp:
            for case in cases:
                work = Path(tmp) / case.replace(":", "_")
                r = results.setdefault(label, {})[case] = run_child(
                    CHILD, code, case, str(work), str(ROOT), cache=Path(tmp) / "cache")
                starts = ", ".join(f"{k} {v:.3g}" for k, v in r["start"].items())
                print(f"{label:18s} {case:52s} {r['status']:42s} {r['iterations']:4d} it, "
                      f"chi2/dof {r['chi2_dof']:.3f}, {r['seconds']:.0f} s; starts: {starts}"
                      + (f"; {r['how']}" if "restarted" in r["how"] else ""), flush=True)
    rows = [{"tree": label, "case": case, "starts": ", ".join(
                f"{k} {v:.3g}" for k, v in r["start"].items()),
             "status": r["status"], "iterations": r["iterations"], "chi2_dof": r["chi2_dof"],
             "seconds": r["seconds"]}
            for label, by_case in results.items() for case, r in by_case.items()]
    harness.report("rocket_starts", fits=rows)


if __name__ == "__main__":
    main()
