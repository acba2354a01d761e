"""Benchmark: this tree's reconstruction against a git revision's, fit by fit, same data.

Per case (the built-in problems, or `drogue` with an effect hidden and fitted
without it, as in `iteration_cost`), the test folder is simulated once (seed 1
unless `--seed`) and fitted from the offline reduction with the default
settings by each code tree, alternately, `--repeat` times, each fit in a fresh
process.  A tree's first build of a model compiles its native code into that
tree's own cache (the first repeat's "first build" includes the compiler's
time); the fit is timed on a second, warm build.
Printed per fit: build and solve wall time, iterations, time per iteration,
chi-square; then the median ratios (this tree / the revision).

    python benchmarks/revision_cost.py REV [--cases drogue drogue_full drogue+added_mass]
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

import harness
from iteration_cost import make_test
from revisions import ROOT, code_at, run_child

CHILD = r"""
import json, sys, time
from pathlib import Path
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec

folder, misspecified, max_iter = Path(sys.argv[1]), sys.argv[2] == "1", int(sys.argv[3])
test = load_test(folder)
spec = baseline_spec() if misspecified else None
t0 = time.perf_counter()
Estimator(test, spec, Settings(max_iter=max_iter))  # compiles on a tree's first run
first = time.perf_counter() - t0
t0 = time.perf_counter()
est = Estimator(test, spec, Settings(max_iter=max_iter))
build = time.perf_counter() - t0
t0 = time.perf_counter()
try:
    fit = est.solve()
    outcome = {"iterations": fit.solver.iterations, "chi2": fit.chi_square,
               "status": fit.solver.status}
except SolverFailure as exc:
    outcome = {"iterations": exc.iterations, "chi2": float("nan"), "status": exc.status}
solve = time.perf_counter() - t0
print(json.dumps({"first_build_s": first, "build_s": build, "solve_s": solve, **outcome}))
"""


def _medians(runs: list[dict]) -> dict[str, float]:
    """Median build and solve time, time per iteration and chi-square over repeated fits."""
    return {key: statistics.median(r[key] for r in runs) for key in ("build_s", "solve_s", "chi2")
            } | {"per_iteration": statistics.median(r["solve_s"] / max(r["iterations"], 1)
                                                    for r in runs)}


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    parser.add_argument("revision", help="git revision to compare against (e.g. HEAD~1)")
    parser.add_argument("--cases", nargs="+",
                        default=["drogue", "drogue_full", "drogue+added_mass"])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--max-iter", type=int, default=150)
    args = parser.parse_args()
    cases = {}
    with (tempfile.TemporaryDirectory() as tmp, code_at(args.revision) as baseline):
        trees = {"this tree": ROOT, args.revision: baseline}
        caches = {label: Path(tmp) / f"cache-{i}" for i, label in enumerate(trees)}
        for name in args.cases:
            folder = make_test(name, args.seed, Path(tmp))
            runs: dict[str, list[dict]] = {label: [] for label in trees}
            for _ in range(args.repeat):
                for label, code in trees.items():
                    r = run_child(CHILD, code, str(folder), "1" if "+" in name else "0",
                                  str(args.max_iter), cache=caches[label])
                    runs[label].append(r)
                    print(f"{name:18s} {label:>10s}: first build {r['first_build_s']:5.1f} s, "
                          f"build {r['build_s']:5.1f} s, "
                          f"{r['iterations']:3d} it in {r['solve_s']:6.1f} s "
                          f"({r['solve_s'] / max(r['iterations'], 1):.3f} s/it), "
                          f"chi-square {r['chi2']:.3f}, {r['status']}", flush=True)
            new, old = (_medians(r) for r in runs.values())
            ratios = {k: harness.ratio(new[k], old[k])
                      for k in ("build_s", "solve_s", "per_iteration")}
            print(f"{name:18s} this tree / {args.revision}: build "
                  f"{ratios['build_s']:.2f}, solve "
                  f"{ratios['solve_s']:.2f}, time per iteration "
                  f"{ratios['per_iteration']:.2f}, chi-square difference "
                  f"{new['chi2'] - old['chi2']:+.4f}", flush=True)
            cases[name] = {"runs": runs, "medians": {"this tree": new, args.revision: old},
                           "this_tree_over_revision": ratios,
                           "chi_square_difference": new["chi2"] - old["chi2"]}
    harness.report("revision_cost", revision=args.revision, repeat=args.repeat, cases=cases)


if __name__ == "__main__":
    main()
