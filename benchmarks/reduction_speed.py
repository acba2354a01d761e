"""The offline reduction's stage curve fits with CasADi's exact Jacobian, against the
finite differences they replace (`stage_curve_fit`).

Each stage's curve fit (Eqs. 5, 6 on the reduced drag area) is a small bounded least
squares whose residual is a CasADi function mapped over the stage's samples.
scipy's `least_squares` took its Jacobian by forward differences, one more
evaluation per fitted parameter (five for an infinite-mass stage) per iteration;
now residual and Jacobian come from one evaluation of the mapped curve and its
exact derivatives, which costs about two.  Every reconstruction, diagnosis,
window move and restart that builds an estimator from the test folder runs the
reduction.

Each case's reduction (`reduction.reduce_and_guess` with the declared model) runs with
the package of revision REV (default `BEFORE`) and with this tree's, each in a
process of its own, `--repeat` times (the fastest kept).  Printed: the wall time of
each, the ratio now/REV, and the largest change of any guessed parameter relative
to its bounds' range.

Cases: the built-in problems simulated with `--seed`, the three recorder layouts of
the suite's synthetic rocket flight, and the two public rocket logs in
`../shared/data/rocketpy-logs` where present.

    python benchmarks/reduction_speed.py [--against REV] [--seed 1] [--repeat 3]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import harness
from bounded_stop import imported_logs
from revisions import ROOT, code_at, run_child

BEFORE = "026923f"
PROBLEMS = ("drogue", "drogue_full", "main2", "main3", "fbcp")

# Child script: the reduction of a folder, timed `repeat` times (the fastest kept).
REDUCE = r"""
import json, sys, time
from pathlib import Path
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.reduction import reduce_and_guess
from cpas_ocp.io.flight_test import load_test
test = load_test(Path(sys.argv[1]))
model = Estimator(test).model
times = []
for _ in range(int(sys.argv[2])):
    start = time.perf_counter()
    guess, _ = reduce_and_guess(test, model)
    times.append(time.perf_counter() - start)
bounds = {p.name: (p.lower, p.upper) for p in model.parameters}
print(json.dumps({"wall_s": min(times), "guess": guess, "bounds": bounds}))
"""


def cases(root: Path, seed: int) -> dict[str, Path]:
    """The folders reduced, by name."""
    from cpas_ocp.estimation.simulate import simulate_problem
    from cpas_ocp.io.problems import load_problem

    out: dict[str, Path] = {}
    for problem in PROBLEMS:
        simulate_problem(load_problem(problem), root / problem, seed)
        out[f"{problem} seed {seed}"] = root / problem
    return out | imported_logs(root)


def largest_change(old: dict, new: dict) -> tuple[str, float]:
    """The guessed parameter that changed most, and its change as a fraction of its bounds'
    range."""
    changes = {n: abs(new["guess"][n] - v) / max(hi - lo, 1e-300)
               for n, v in old["guess"].items()
               for lo, hi in [new["bounds"][n]] if n in new["guess"]}
    name = max(changes, key=changes.__getitem__)
    return name, changes[name]


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated problems")
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, code_at(args.against) as before:
        for name, folder in cases(Path(tmp), args.seed).items():
            new = run_child(REDUCE, ROOT, str(folder), str(args.repeat))
            try:
                old = run_child(REDUCE, before, str(folder), str(args.repeat))
            except RuntimeError as error:  # a folder the older package cannot read
                reason = str(error).strip().splitlines()[-1]
                rows[name] = {"before_s": None, "now_s": new["wall_s"], "wall_ratio": None,
                              "largest_change": f"not comparable: {args.against} {reason}",
                              "change_of_range": None}
                print(f"{name:20s} now: {new['wall_s']:6.3f} s | not comparable: "
                      f"{args.against} {reason}", flush=True)
                continue
            worst, change = largest_change(old, new)
            rows[name] = {"before_s": old["wall_s"], "now_s": new["wall_s"],
                          "wall_ratio": harness.ratio(new["wall_s"], old["wall_s"]),
                          "largest_change": worst, "change_of_range": change}
            print(f"{name:20s} {args.against}: {old['wall_s']:6.3f} s | now: "
                  f"{new['wall_s']:6.3f} s | ratio "
                  f"{harness.ratio_text(new['wall_s'], old['wall_s'])} | largest change "
                  f"{change:.1e} of the range ({worst})", flush=True)
    harness.report("reduction_speed", against=args.against, cases=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
