"""The reported 95 % intervals of the `drogue` reconstruction cover the truth 95 % of the time.

Seeds 1-5 (start guesses 0.3 s off), every free parameter not on a bound:
41 intervals estimate +- 1.959964 sigma per seed, 205 in all.

Two checks, one per way the covariance can be wrong:

- Sigmas too small, i.e. coverage collapses: the pooled coverage must reach
  MIN_POOLED_COVERAGE (derivation below).
- Sigmas too large, i.e. intervals needlessly wide: a coverage ceiling is a
  weak test, since at nominal only about 10 of 205 intervals miss.  The check
  is instead the sum over seeds of the squared Mahalanobis distance of
  estimate from truth, which is chi-square on the summed rank (about 200) if
  the covariance is right.  Unlike the mean of z^2 it stays chi-square when
  the parameters are correlated.  Sigmas 2x too large divide it by 4 (to
  about 50), and 1.5x too large by 2.25 (to about 89).  Both fall far below
  the chi-square 0.001 quantile on 200 dof (144).

`benchmarks/drogue_coverage.py` runs the same scoring on 100 seeds, per
parameter.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

pytestmark = pytest.mark.slow

SEEDS = [1, 2, 3, 4, 5]
Z95 = 1.959964
# Pooled coverage floor.  At nominal 95 % the number covered among n = 205
# intervals would be binomial if the intervals were independent: standard
# deviation sqrt(0.95 * 0.05 / 205) = 1.5 percentage points.  One seed's
# intervals are correlated (a start time with its stage's shape parameters,
# the drag with the load-cell scales), so they cover or miss together.  Drawn
# from the reported correlations, the count's variance is about 3x the
# binomial one, which puts the standard deviation near 2.6 points.  The floor
# 0.87 is 8 points (over 5 binomial, 3 correlated standard deviations) below
# nominal.  Sigmas underestimated by 1.5x give P(|Z| < 1.96 / 1.5) = 81 %
# coverage, 6 points (about 1.3 correlated standard deviations) below the
# floor: most such collapses fail, not all.  In the 100-seed study, with every
# z multiplied by 1.5, 17 of its 20 disjoint five-seed blocks fall below the
# floor; unscaled, the lowest block is at 89.3 %.
MIN_POOLED_COVERAGE = 0.87
# Lower chi-square quantile for the pooled squared Mahalanobis distance.
MAHALANOBIS_LOWER_QUANTILE = 0.001


def test_pooled_coverage_of_95_percent_intervals(drogue_fit) -> None:
    covered, z_all, m2_sum, dof_sum = [], [], 0.0, 0
    for seed in SEEDS:
        fit, cov, truth = drogue_fit(seed)
        std = cov.std
        names = [n for n in fit.free if n not in cov.at_bound]
        z = np.array([(fit.parameters[n] - truth[n]) / std[n] for n in names])
        covered.extend(np.abs(z) < Z95)
        z_all.extend(z)
        m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
        m2_sum += m2
        dof_sum += dof
    coverage = float(np.mean(covered))
    summary = (f"pooled coverage {100 * coverage:.1f} % of {len(covered)}, mean z^2 "
               f"{np.mean(np.square(z_all)):.2f}, Mahalanobis^2 {m2_sum:.1f} on {dof_sum} dof")
    assert coverage >= MIN_POOLED_COVERAGE, summary
    assert m2_sum > chi2.ppf(MAHALANOBIS_LOWER_QUANTILE, dof_sum), summary
