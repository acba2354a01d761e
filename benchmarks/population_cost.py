"""Benchmark: a grouping test's bootstrap with the BLAS pools found once against found at
every population fit, in the same process.

`fit_population` runs each fit with BLAS on one thread.  The earlier path,
`threadpool_limits(1)`, looks the process's BLAS and OpenMP libraries up at
every call; the current one finds them once (`population_model._blas`).  A
grouping test of three parameters with a full Omega on 24 openings, Bartlett-
adjusted by 40 bootstrap campaigns, makes 124 such fits.  The campaign is
drawn (seed 1 unless `--seed`) from a known population as in
`tests/campaign/test_population.py`; the package is imported whole first, so
the process holds the libraries a command's does.  Both paths run `--repeats`
times, alternating; printed: the median wall time of each and their ratio, and
that both give the same statistic and Bartlett factor.

    python benchmarks/population_cost.py [--repeats 3] [--seed 1]
"""

from __future__ import annotations

import statistics

import harness
import numpy as np
from threadpoolctl import ThreadpoolController

import cpas_ocp.api  # noqa: F401  (the libraries a command's process holds)
from cpas_ocp.campaign import population_model
from cpas_ocp.campaign.population_model import PopulationData, grouping_test

TAU = np.array([0.10, 0.15, 0.08])
RHO = np.array([[1.0, -0.5, 0.2], [-0.5, 1.0, 0.0], [0.2, 0.0, 1.0]])
MEAN = np.array([np.log(2.0), np.log(9.0), np.log(1.5)])


def draw(seed: int, n: int = 24, k: int = 3, noise: float = 0.03) -> PopulationData:
    """`n` openings of a k-parameter population, each estimate's standard deviations `noise`
    times a factor in [0.5, 2], correlated 0.4 within a test."""
    rng = np.random.default_rng(seed)
    omega = RHO[:k, :k] * np.outer(TAU[:k], TAU[:k])
    sd = noise * rng.uniform(0.5, 2.0, (n, 1)) * np.ones(k)
    V = (0.6 * np.eye(k) + 0.4)[None] * sd[:, :, None] * sd[:, None, :]
    theta = MEAN[:k] + rng.multivariate_normal(np.zeros(k), omega, n)
    y = theta + np.array([rng.multivariate_normal(np.zeros(k), v) for v in V])
    return PopulationData(tuple("abc"[:k]), tuple(f"t{i} c1" for i in range(n)), y, V,
                          np.ones((n, 1)), ("intercept",), (True,) * k)


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the drawn campaign")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    data = draw(args.seed)
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
