"""A fit's shape restarts without the one that repeats the first fit
(`shape_restarts.restart_shapes`), against the restarts that solved it again.

Where a fit ends with an opening's shape on a guessed bound, it is solved again from the
reduction with the stage's shapes at 1, 0.5 and 2 times their defaults.  Where the
reduction had left those shapes at their defaults (a stage an altimeter alone barely
sees), the start at 1 times is the reduction's own, and the solve, being deterministic,
repeated the first fit iteration for iteration; it is now skipped.

Each case is reconstructed as `cpas-ocp reconstruct` fits it (`continuation.solve_checked`:
the first fit, its shape and start-time restarts, window moves, the claim) with the
package of revision REV (default `BEFORE`, the last that solved the repeat) and with this
tree's, each in a process of its own, after an untimed run that compiles the models both
use into one cache (`revisions.call_at`).  Printed: the solves made, chi-square, how the
kept fit started and the wall time of each, and the ratio of wall times now/REV.

Cases: the three recorder layouts of the suite's synthetic rocket flight and the two
public rocket logs in `../shared/data/rocketpy-logs` where present
(`bounded_stop.imported_logs`).

    python benchmarks/shape_restarts.py [--against REV]
"""

from __future__ import annotations

import sys
from pathlib import Path

import harness
from bounded_stop import imported_logs
from revisions import compare_cases

BEFORE = "3050262"


def checked(folder: str) -> dict:
    """`solve_checked` on `folder`'s declared model: the solves it made, chi-square, where the
    kept fit started and the wall time (for `call_at`)."""
    from cpas_ocp.estimation.estimator import Estimator
    from cpas_ocp.inference.continuation import solve_checked
    from cpas_ocp.io.flight_test import load_test

    solves = 0
    solve = Estimator.solve

    def counted(self: Estimator, *args: object, **kwargs: object) -> object:
        nonlocal solves
        solves += 1
        return solve(self, *args, **kwargs)

    Estimator.solve = counted
    timer = harness.Timer()
    with timer("fit"):
        _, fit, _ = solve_checked(Estimator(load_test(Path(folder))))
    return {"solves": solves, "chi_square": fit.chi_square, "start": fit.solver.start,
            "wall_s": timer["fit"]}


def main() -> int:
    parser = harness.parser(__doc__, None)
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    args = parser.parse_args()
    compare_cases("shape_restarts", "checked", imported_logs, args.against,
                  lambda r: f"{r['solves']} solves, chi2 {r['chi_square']:10.4f}, "
                            f"{r['wall_s']:5.1f} s, kept fit from {r['start']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
