"""Trial points judged from values: the fit and claim of a `reconstruct`, with the package of
revision REV (default `BEFORE`) and with this tree's.

A feasible point (`StartingPoints.feasible_point`) and a point's chi-square and
violation (`Linearisations.evaluate`) are asked of every trial a descent, a
restart or a start makes.  At REV both evaluated the constraint Jacobian, and
`evaluate` the residual Jacobian too, by linearising the point; most trials
are rejected and never linearised.  Now both evaluate the residuals' and the
constraints' values alone (the Jacobian only where an effect's own
constraints need it), and a point that is kept is linearised when it is used.
On a real log's model the constraint Jacobian costs four times its values
(NDRT 2020: 245,772 nonzeros, 9.7 ms in the VM against 2.4 ms).

Per case, `api.reconstruction.fit_estimator` (the fit, its restarts and the
claim: what every command that fits runs) on the case's folder with its own
model, each tree alternately, `--repeat` times, each in a fresh process with
its models compiled first into a cache both trees share.  Printed: the median
wall time of each, the ratio now/REV, the Jacobian evaluations made (residual
`rJ`, constraint `gA`) and chi-square on each side.

Cases: `drogue` simulated with `--seed`, the suite's synthetic rocket flight through a
column map, and the public rocket logs in `../shared/data/rocketpy-logs` where present.

    python benchmarks/trial_evaluations.py [--against REV] [--repeat 3]
"""

from __future__ import annotations

import statistics
import sys
import tempfile
from pathlib import Path

import harness
from bounded_stop import imported_logs
from iteration_cost import make_test
from revisions import code_at, run_child

BEFORE = "e1ca4e6"

# Child script: one fit and claim of a folder with its own model, timed.
FIT = r"""
import json, sys, time
from cpas_ocp.api.reconstruction import as_test, build, fit_estimator, model_of
test = as_test(sys.argv[1])
est = build(test, model_of(test))
t0 = time.perf_counter()
rec = fit_estimator(est)
wall = time.perf_counter() - t0
made = rec.estimator.transcription.points.evaluations
print(json.dumps({"wall_s": wall, "rJ": made["rJ"], "gA": made["gA"],
                  "chi2": rec.fit.chi_square, "status": rec.fit.solver.status}))
"""


def cases(root: Path, seed: int) -> dict[str, Path]:
    """The folders fitted, by name."""
    found = {"drogue": Path(make_test("drogue", seed, root))}
    for name, folder in imported_logs(root).items():
        if name in ("columns import", "ndrt_2020", "genesis_2023"):
            found[name] = folder
    return found


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue test")
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, code_at(args.against) as before:
        trees = {args.against: before, "now": Path(__file__).resolve().parents[1]}
        cache = Path(tmp) / "cache"
        for name, folder in cases(Path(tmp), args.seed).items():
            runs: dict[str, list[dict]] = {label: [] for label in trees}
            run_child(FIT, trees["now"], str(folder), cache=cache, compile_first=True)
            for _ in range(args.repeat):
                for label, code in trees.items():
                    runs[label].append(run_child(FIT, code, str(folder), cache=cache,
                                                 compile_first=True))
            old, new = runs[args.against], runs["now"]
            wall_old = statistics.median(r["wall_s"] for r in old)
            wall_new = statistics.median(r["wall_s"] for r in new)
            rows[name] = {"before_s": wall_old, "now_s": wall_new,
                          "wall_ratio": harness.ratio(wall_new, wall_old),
                          "before": old[0] | {"wall_s": wall_old},
                          "now": new[0] | {"wall_s": wall_new}}
            print(f"{name:16s} {args.against}: {wall_old:6.2f} s, rJ {old[0]['rJ']:4d}, "
                  f"gA {old[0]['gA']:4d}, chi2 {old[0]['chi2']:.6f} | now: {wall_new:6.2f} s, "
                  f"rJ {new[0]['rJ']:4d}, gA {new[0]['gA']:4d}, chi2 {new[0]['chi2']:.6f} | "
                  f"ratio {harness.ratio_text(wall_new, wall_old)}", flush=True)
    harness.report("trial_evaluations", against=args.against, cases=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
