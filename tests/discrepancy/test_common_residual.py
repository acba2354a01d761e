"""The shared-residual test: two sensors of the altitude that see the same wander.

A slow wander common to both channels is the vehicle's motion; one that each
channel has on its own is that sensor's error.  Seeded residuals of both
kinds check the test's power and its false-alarm rate.
"""

from __future__ import annotations

import numpy as np

from cpas_ocp.discrepancy.common_residual import combined_p_value, shared_residuals
from cpas_ocp.estimation.estimator import SensorResidual

SPANS = [(0.0, 130.0), (130.0, 195.0)]  # two canopy phases (s), as in a rocket's descent


def _wander(rng: np.random.Generator, t: np.ndarray, amplitude: float) -> np.ndarray:
    """A slow random wander (m): smoothed white noise with a 20 s correlation time."""
    fine = np.arange(t[0] - 60.0, t[-1] + 60.0, 1.0)
    kernel = np.exp(-0.5 * (np.arange(-60, 61) / 20.0) ** 2)
    w = np.convolve(rng.standard_normal(fine.size), kernel / np.sqrt(kernel @ kernel), "same")
    return amplitude * np.interp(t, fine, w)


def _channels(seed: int, shared: bool) -> tuple[SensorResidual, SensorResidual]:
    """An altimeter at 10 Hz (sigma 3 m) and a GPS at 1 Hz (sigma 4 m) with a 8 m wander
    that both see (shared) or that each has its own of."""
    rng = np.random.default_rng(seed)
    tb, tg = np.arange(0.0, 195.0, 0.1), np.arange(0.0, 195.0, 1.0)
    wb = _wander(rng, tb, 8.0)
    wg = np.interp(tg, tb, wb) if shared else _wander(rng, tg, 8.0)
    baro = SensorResidual("baro", "altitude", tb, wb + 3.0 * rng.standard_normal(tb.size),
                          np.zeros(tb.size), np.full(tb.size, 3.0))
    gps = SensorResidual("gps_altitude", "up", tg, wg + 4.0 * rng.standard_normal(tg.size),
                         np.zeros(tg.size), np.full(tg.size, 4.0))
    return baro, gps


def test_a_shared_wander_is_found() -> None:
    found = shared_residuals(*_channels(1, shared=True), SPANS)
    assert len(found) == 2
    assert all(c.r > 0.7 for c in found)
    assert combined_p_value(found) < 0.01


def test_wanders_of_their_own_raise_few_false_alarms() -> None:
    # Under the null (independent wanders) the combined p-value falls below 0.05 in at most
    # 5 % of draws, plus three binomial standard errors of the 200-draw estimate.
    draws = 200
    rejected = sum(combined_p_value(shared_residuals(*_channels(seed, shared=False), SPANS))
                   < 0.05 for seed in range(draws))
    assert rejected / draws <= 0.05 + 3.0 * np.sqrt(0.05 * 0.95 / draws)


def test_power_against_a_shared_wander() -> None:
    # At the same 0.05 level the test finds a shared 8 m wander in nearly every draw (98 % of
    # 200 draws when written; at the 0.01 level, 70 %: three minutes of a wander with a 20 s
    # correlation time hold few independent samples).
    draws = 100
    found = sum(combined_p_value(shared_residuals(*_channels(seed, shared=True), SPANS))
                < 0.05 for seed in range(draws))
    assert found / draws > 0.9
