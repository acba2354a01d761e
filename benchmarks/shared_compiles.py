"""Benchmark: two processes that meet the same model with an empty cache, before and after
compiles were claimed across processes.

Two processes start at once, as two suite or campaign workers do, each building
the estimator of the same simulated `drogue` test (seed 1 unless `--seed`) with
its model compiled first (CPAS_OCP_COMPILE=wait) into one shared, empty cache.
Before (`--rev`, default the last commit without claims), each compiled every
library the model needs; after, a library one process has claimed is waited for
by the other (`compiled._claim`).  Printed per side, over `--repeats` runs
alternating: the libraries the two compiled between them, the later process's
build time, and the ratios after/before.

    python benchmarks/shared_compiles.py [--rev 7efe01a] [--repeats 3] [--seed 1]
"""

from __future__ import annotations

import statistics
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import harness
from revisions import ROOT, code_at, run_child

from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem

# Builds the estimator of the test folder argv[1]; prints the libraries compiled and the
# build's wall time.
CHILD = r"""
import json, sys, time
from cpas_ocp.estimation import compiled
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test
began = time.perf_counter()
Estimator(load_test(sys.argv[1]))
print(json.dumps({"libraries": compiled.COUNTS["libraries"],
                  "build_s": time.perf_counter() - began}))
"""


def pair(code: Path, folder: Path) -> dict[str, float]:
    """Two processes building `folder`'s estimator at once into one new empty cache: the
    libraries they compiled between them and the later one's build time."""
    with tempfile.TemporaryDirectory() as cache, ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda _: run_child(CHILD, code, str(folder), cache=Path(cache),
                                                 compile_first=True), range(2)))
    return {"libraries": sum(r["libraries"] for r in runs),
            "build_s": max(r["build_s"] for r in runs)}


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated test")
    parser.add_argument("--rev", default="7efe01a")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    sides: dict[str, list[dict[str, float]]] = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as tmp, code_at(args.rev) as before:
        folder = Path(tmp) / "drogue"
        simulate_problem(load_problem("drogue"), folder, args.seed)
        for _ in range(args.repeats):
            for label, tree in (("before", before), ("after", ROOT)):
                sides[label].append(pair(tree, folder))
    median = {label: {key: statistics.median(r[key] for r in runs)
                      for key in ("libraries", "build_s")} for label, runs in sides.items()}
    ratios = {key: harness.ratio(median["after"][key], median["before"][key])
              for key in ("libraries", "build_s")}
    for label in sides:
        print(f"{label:6s}: {median[label]['libraries']:.0f} libraries compiled by the two, "
              f"the later build {median[label]['build_s']:.1f} s (median of {args.repeats})")
    print(f"after/before: libraries {ratios['libraries']:.2f}, build time "
          f"{ratios['build_s']:.2f}")
    harness.report("shared_compiles", rev=args.rev, median=median, ratios=ratios,
                   runs=sides)


if __name__ == "__main__":
    main()
