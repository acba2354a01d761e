"""The population fit's calibration over many drawn populations: its intervals cover the
truth as often as their level says, and the grouping test pools alike sets and separates
shifted ones (`tests/campaign/test_population.py` holds the single-population checks)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from cpas_ocp.campaign.population_model import fit_population, grouping_test
from tests.campaign.test_population import EFFECT, MEAN, TAU, _binomial_range, draw


@pytest.mark.slow
def test_intervals_cover_at_their_level() -> None:
    """Over 120 populations of 16 openings (two parameters, a covariate): every coefficient's
    and tau's 95 % interval covers the truth as often as a binomial allows."""
    reps, k = 120, 2
    hits = {"beta": [], "tau": []}
    for seed in range(reps):
        data = draw(seed=100 + seed, n=16, k=k)
        fit = fit_population(data)
        truth = np.column_stack([MEAN, EFFECT])[:k]
        hits["beta"].append([fit.coefficients[(n, c)].covers(truth[j, a])
                             for j, n in enumerate(data.names)
                             for a, c in enumerate(data.columns)])
        hits["tau"].append([fit.tau[n].covers(TAU[j]) for j, n in enumerate(data.names)])
    lo, hi = _binomial_range(reps, 0.95, 2 * k + k)
    for key, rows in hits.items():
        rates = np.mean(rows, axis=0)
        assert ((rates >= lo) & (rates <= hi)).all(), (key, rates, lo, hi)


@pytest.mark.slow
def test_grouping_keeps_one_population_and_separates_a_shifted_one() -> None:
    """Two sets of 20 openings of two parameters: drawn alike they are pooled as often as
    the level says (the chi-square law as it is: 10 openings per parameter apart);
    shifted by two between-test sigmas in every parameter they are separated in at least
    80 % of the draws."""
    reps = 60
    kept, split = [], []
    for seed in range(reps):
        labels = ["A"] * 20 + ["B"] * 20
        for shift, out in ((0.0, kept), (2.0, split)):
            data = draw(seed=500 + seed, n=40, k=2, shift=shift, noise=0.02)
            intercept = data.subset(np.arange(40), keep_columns=[0])
            out.append(grouping_test(intercept, labels, "type", bootstrap=0).separate)
    _, hi = stats.binom.ppf([0.005, 0.995], reps, 0.05)
    assert sum(kept) <= hi
    assert np.mean(split) >= 0.8
