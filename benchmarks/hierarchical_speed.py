"""Benchmark: the hierarchical fit's solves, ended at Ipopt's iterates by the statistical test
and warm-started from their neighbour's solution, against the older path (Ipopt's own
acceptable-point tests first, every solve from the default barrier), on the same tests.

The tests are those of `hierarchical_coverage.py` (the `fbcp` problem with poor load
cells, each canopy's CdS drawn from a population), `--tests` of them drawn with
`--seed`.  Printed: each path's wall time and solves, the ratio old/new, and how far
the two estimates of the median and tau lie apart (in the median's sigma, and in log).

    python benchmarks/hierarchical_speed.py [--tests 4] [--seed 1]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import harness
import numpy as np
from hierarchical_coverage import NAME, simulated_tests

from cpas_ocp.errors import SolverFailure
from cpas_ocp.inference.hierarchical_fit import hierarchical_fit


def main() -> None:
    ap = harness.parser(__doc__, seed=1)
    ap.add_argument("--tests", type=int, default=4, help="tests in the campaign (default 4)")
    args = ap.parse_args()
    timer = harness.Timer()
    with tempfile.TemporaryDirectory() as tmp:
        tests = simulated_tests(args.seed, args.tests, Path(tmp))
        fits, failures = {}, {}
        for label, fast in (("new", True), ("old", False)):
            try:
                with timer(label):
                    fits[label] = hierarchical_fit(tests, {"CdS": "type"}, monitor=fast,
                                                   warm=fast)
                print(f"{label}: {timer[label]:.0f} s, {fits[label].evaluations} solves",
                      flush=True)
            except SolverFailure as exc:  # the path's outcome, timed to its failure
                failures[label] = str(exc)
                print(f"{label}: failed after {timer[label]:.0f} s: {exc}", flush=True)
    print(f"speed-up (old / new wall time): {harness.ratio_text(timer['old'], timer['new'])}"
          + (" (to the old path's failure)" if "old" in failures else ""))
    result = {"tests": args.tests, "new_s": timer["new"], "old_s": timer["old"],
              "speed_up": harness.ratio(timer["old"], timer["new"]), "failures": failures}
    if len(fits) == 2:
        new, old = fits["new"].estimate(NAME), fits["old"].estimate(NAME)
        apart = abs(np.log(new.median / old.median)) / new.mu_std
        print(f"medians {new.median:.4f} and {old.median:.4f} m^2 ({apart:.2f} sigma apart); "
              f"tau {new.tau:.4f} and {old.tau:.4f}")
        result |= {"new_solves": fits["new"].evaluations, "old_solves": fits["old"].evaluations,
                   "median_apart_sigma": apart, "tau_new": new.tau, "tau_old": old.tau}
    harness.report("hierarchical_speed", **result)


if __name__ == "__main__":
    sys.exit(main())
