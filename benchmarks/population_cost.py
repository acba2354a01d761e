"""Benchmark: a grouping test's bootstrap with the BLAS pools found once against found at
every population fit, in the same process.

`fit_population` runs each fit with BLAS on one thread.  The earlier path,
`threadpool_limits(1)`, looks the process's BLAS and OpenMP libraries up at
every call; the current one finds them once (`population_model._blas`).  A
grouping test of three parameters with a full Omega on 24 openings, Bartlett-
adjusted by 40 bootstrap campaigns, makes 124 such fits.  The campaign is
drawn (seed 1 unless `--seed`) by `tests/campaign/test_population.py`'s own
generator, as its Bartlett-factor test draws it; the package is imported whole first, so
the process holds the libraries a command's does.  Both paths run `--repeats`
times, alternating; printed: the median wall time of each and their ratio, and
that both give the same statistic and Bartlett factor.

    python benchmarks/population_cost.py [--repeats 3] [--seed 1]
"""

from __future__ import annotations

import statistics
import sys

import harness
import numpy as np
from revisions import ROOT
from threadpoolctl import ThreadpoolController

import cpas_ocp.api  # noqa: F401  (the libraries a command's process holds)
from cpas_ocp.campaign import population_model
from cpas_ocp.campaign.population_model import grouping_test

sys.path.insert(0, str(ROOT))
from tests.campaign.test_population import draw


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the drawn campaign")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    data = draw(seed=args.seed, n=24, k=3, effect=False).subset(np.arange(24),
                                                                 keep_columns=[0])
    labels = ["A"] * 12 + ["B"] * 12
    found_once = population_model._blas
    paths = {"every fit": ThreadpoolController, "once": found_once}
    walls: dict[str, list[float]] = {label: [] for label in paths}
    results = {}
    for _ in range(args.repeats):
        for label, blas in paths.items():
            population_model._blas = blas
            timer = harness.Timer()
            with timer("grouping"):
                test = grouping_test(data, labels, "type", bootstrap=40, seed=3)
            walls[label].append(timer["grouping"])
            results[label] = (test.statistic, test.bartlett)
    population_model._blas = found_once
    median = {label: statistics.median(w) for label, w in walls.items()}
    ratio = harness.ratio(median["once"], median["every fit"])
    same = results["once"] == results["every fit"]
    for label in paths:
        print(f"BLAS pools found {label:9s}: median {median[label]:.2f} s over "
              f"{args.repeats} runs")
    print(f"once / every fit: {ratio:.2f}; the same statistic and Bartlett factor: {same}")
    harness.report("population_cost", median_s=median, ratio=ratio, same_result=same)


if __name__ == "__main__":
    main()
