"""Normal points: bins of a densely sampled series keep its information and its value where
the signal is linear, and leave the kept windows as they are."""

from __future__ import annotations

import numpy as np

from cpas_ocp.normal_points import normal_points


def test_bins_keep_a_linear_signal_and_its_information() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    y = 2000.0 - 12.0 * t  # a steady descent at 12 m/s (m)
    sigma = np.full(t.size, 0.3)
    keep = [(10.0, 15.0)]
    times, values, sigmas = normal_points(t, y, sigma, keep, max_bin_s=0.5)
    assert np.all(np.diff(times) > 0.0)
    np.testing.assert_allclose(values, 2000.0 - 12.0 * times, atol=1e-9)
    # Fisher information 1/sigma^2 summed over the samples is unchanged.
    assert np.isclose(np.sum(sigmas**-2), np.sum(sigma**-2))
    kept = (t >= 10.0) & (t <= 15.0)
    inside = (times >= 10.0) & (times <= 15.0)
    np.testing.assert_array_equal(times[inside], t[kept])
    np.testing.assert_array_equal(sigmas[inside], 0.3)
    binned = sigmas < 0.3
    np.testing.assert_allclose(sigmas[binned], 0.3 / np.sqrt(50))
    assert binned.sum() == 20 + 89  # 0-10 s and 15-60 s in bins of 50 samples


def test_a_bin_averages_the_noise_down_by_its_size() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 500.0, 0.01)
    noise = rng.normal(0.0, 0.3, t.size)
    _, values, sigmas = normal_points(t, noise, np.full(t.size, 0.3), [])
    # Normalised by their own sigma the bins' means scatter with unit variance.
    z = values / sigmas
    assert abs(np.std(z) - 1.0) < 3.0 / np.sqrt(2 * z.size)
