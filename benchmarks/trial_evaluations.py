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
its models compiled first into a cache both trees share
(`revisions.compare_cases`).  Printed: the median wall time of each, the ratio
now/REV, the Jacobian evaluations made (residual `rJ`, constraint `gA`) and
chi-square on each side.

Cases: `drogue` simulated with `--seed`, the suite's synthetic rocket flight through a
column map, and the public rocket logs in `../shared/data/rocketpy-logs` where present.

    python benchmarks/trial_evaluations.py [--against REV] [--repeat 3]
"""

from __future__ import annotations

import sys
from pathlib import Path

import harness
from bounded_stop import imported_logs
from iteration_cost import make_test
from revisions import compare_cases

BEFORE = "e1ca4e6"


def fitted(folder: str) -> dict:
    """One fit and claim of `folder` with its own model: wall time, Jacobian evaluations,
    chi-square and status."""
    from cpas_ocp.api.reconstruction import as_test, build, fit_estimator, model_of

    test = as_test(folder)
    est = build(test, model_of(test))
    timer = harness.Timer()
    with timer("fit"):
        rec = fit_estimator(est)
    made = rec.estimator.transcription.points.evaluations
    return {"wall_s": timer["fit"], "rJ": made["rJ"], "gA": made["gA"],
            "chi2": rec.fit.chi_square, "status": rec.fit.solver.status}


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
    compare_cases("trial_evaluations", "fitted", lambda root: cases(root, args.seed),
                  args.against,
                  lambda r: f"{r['wall_s']:6.2f} s, rJ {r['rJ']:4d}, gA {r['gA']:4d}, "
                            f"chi2 {r['chi2']:.6f}", repeat=args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
