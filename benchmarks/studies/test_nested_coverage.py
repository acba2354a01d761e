"""The test-level and canopy-level population's calibration (`campaign/nested_population.py`):
over 200 campaigns of 20 two-canopy tests drawn from the model, with a test-level spread in
both parameters, a canopy-level spread in one and none in the other (a boundary), and the
two canopies' CdS estimates correlated -0.9, each interval covers its truth as often as a
binomial allows at its 95 % level (about 80 s)."""

from __future__ import annotations

import numpy as np
import pytest

from cpas_ocp.campaign.nested_population import fit_nested
from tests.campaign.test_nested_population import MEAN, draw_tests
from tests.campaign.test_population import _binomial_range

TAU_TEST, TAU_CANOPY = (0.05, 0.04), (0.0, 0.03)


@pytest.mark.slow
def test_the_nested_intervals_cover_at_their_level() -> None:
    reps = 200
    hits = []
    for seed in range(reps):
        data = draw_tests(1000 + seed, 20, TAU_TEST, TAU_CANOPY)
        fit = fit_nested(data)
        hits.append([fit.coefficients[(n, "intercept")].covers(MEAN[j])
                     for j, n in enumerate(data.names)]
                    + [fit.tau_test[n].covers(TAU_TEST[j]) for j, n in enumerate(data.names)]
                    + [fit.tau_canopy[n].covers(TAU_CANOPY[j])
                       for j, n in enumerate(data.names)])
    rates = np.mean(hits, axis=0)
    lo, hi = _binomial_range(reps, 0.95, len(rates))
    assert ((rates >= lo) & (rates <= hi)).all(), (rates, lo, hi)
