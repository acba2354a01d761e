"""Whiteness, periodicity and lag tests on synthetic residuals with known content.

White noise: over 200 seeded series each test flags p < 0.05 about 10 times;
the band asserted is the binomial(200, 0.05) 0.001-0.999 range, so a test
whose p-values are not uniform under the null (a wrong degrees-of-freedom
count, a missing normalisation) fails it.  A sinusoid of 0.3 sigma, a lag of
20 ms: found, at the right frequency (within one periodogram bin) and the
right lag (within 4 standard errors).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from cpas_ocp.discrepancy.residual_tests import lag, ljung_box, periodicity

RATE_HZ = 100.0
N = 2000
SERIES = 200


def test_white_noise_is_flagged_at_the_nominal_rate() -> None:
    rng = np.random.default_rng(2024)
    lo, hi = binom.ppf([0.001, 0.999], SERIES, 0.05)
    flagged_lb = flagged_fisher = 0
    for _ in range(SERIES):
        e = rng.standard_normal(N)
        flagged_lb += ljung_box(e).p_value < 0.05
        flagged_fisher += periodicity(e, RATE_HZ).p_value < 0.05
    assert lo <= flagged_lb <= hi, flagged_lb
    assert lo <= flagged_fisher <= hi, flagged_fisher


def test_a_small_oscillation_is_found_at_its_frequency() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(N) / RATE_HZ
    e = rng.standard_normal(N) + 0.3 * np.sin(2 * np.pi * 7.0 * t + 0.4)
    found = periodicity(e, RATE_HZ)
    assert found.p_value < 1e-6
    assert found.value == pytest.approx(7.0, abs=RATE_HZ / N)
    assert ljung_box(e).p_value < 1e-3


def test_a_sensor_lag_is_estimated_with_its_standard_error() -> None:
    rng = np.random.default_rng(11)
    t = np.arange(N) / RATE_HZ
    sigma = np.full(N, 0.5)

    def h(time: np.ndarray) -> np.ndarray:  # an output with ramps and a transient
        return 40.0 * np.tanh(time - 6.0) + 10.0 * np.sin(0.9 * time)

    y = h(t - 0.02) + sigma * rng.standard_normal(N)
    found = lag((y - h(t)) / sigma, h(t), sigma, t)
    assert found.std < 0.005
    assert abs(found.value - 0.02) < 4 * found.std
    assert found.p_value < 1e-6
    y0 = h(t) + sigma * rng.standard_normal(N)
    assert abs(lag((y0 - h(t)) / sigma, h(t), sigma, t).statistic) < 4


def test_too_short_or_flat_series_are_refused() -> None:
    with pytest.raises(ValueError, match="too few"):
        ljung_box(np.ones(3), lags=5)
    t = np.arange(50) / RATE_HZ
    with pytest.raises(ValueError, match="does not change"):
        lag(np.zeros(50), np.ones(50), np.ones(50), t)
