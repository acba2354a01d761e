"""Distribution fits of campaign parameters: recovery, family choice, caps and bad input.

Tolerances come from sampling noise: the maximum-likelihood mean and standard
deviation of n draws have standard errors sigma/sqrt(n) and
sigma/sqrt(2 n); a uniform's support estimate errs by about (b - a)/n.
Draws from the capped distribution are checked against its truncated CDF with
a Kolmogorov-Smirnov test (valid here: that CDF is fixed, not fitted to the
draws), failing only below p = 1e-3.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from cpas_ocp.campaign.distributions import Dispersion, fit_dispersion

N_LARGE = 20_000
N_SE = 4.0  # allowed error in standard errors for asymptotically normal estimators
P_MIN = 1e-3


def test_normal_parameters_recovered() -> None:
    mean, std = 1.5, 0.2
    x = np.random.default_rng(11).normal(mean, std, N_LARGE)
    d = fit_dispersion("Ck", x)
    assert d.family == "normal"
    assert abs(d.parameters["mean"] - mean) < N_SE * std / np.sqrt(N_LARGE)
    assert abs(d.parameters["std"] - std) < N_SE * std / np.sqrt(2 * N_LARGE)


def test_lognormal_parameters_recovered() -> None:
    mu_log, sigma_log = np.log(3.0), 0.5
    x = np.random.default_rng(12).lognormal(mu_log, sigma_log, N_LARGE)
    d = fit_dispersion("n_p", x)
    assert d.family == "lognormal"
    assert abs(d.parameters["mu_log"] - mu_log) < N_SE * sigma_log / np.sqrt(N_LARGE)
    assert abs(d.parameters["sigma_log"] - sigma_log) < N_SE * sigma_log / np.sqrt(2 * N_LARGE)


def test_uniform_bounds_recovered() -> None:
    a, b = 1.0, 3.0
    x = np.random.default_rng(13).uniform(a, b, N_LARGE)
    # the sample minimum exceeds a by (b - a)/n times an Exp(1) variable: P(> 6) = 0.25 %
    step = (b - a) / N_LARGE
    unbiased = fit_dispersion("expopen", x)
    assert unbiased.family == "uniform"
    assert abs(unbiased.parameters["lower"] - a) < 6 * step
    assert abs(unbiased.parameters["upper"] - b) < 6 * step
    ml = fit_dispersion("expopen", x, uniform_bounds="ml")
    assert ml.family == "uniform"
    assert a <= ml.parameters["lower"] < a + 6 * step
    assert b - 6 * step < ml.parameters["upper"] <= b
    assert unbiased.parameters["lower"] < ml.parameters["lower"]  # widened outward


@pytest.mark.parametrize(("family", "seed"), [("normal", 21), ("lognormal", 22), ("uniform", 23)])
def test_chooser_picks_true_family_of_a_clear_sample(family: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 300
    x = {"normal": lambda: rng.normal(10.0, 2.0, n),
         "lognormal": lambda: rng.lognormal(np.log(10.0), 0.8, n),  # strongly skewed
         "uniform": lambda: rng.uniform(5.0, 15.0, n)}[family]()
    d = fit_dispersion("p", x)
    assert d.family == family
    assert d.gof == min(d.gof_by_family.values())
    assert set(d.gof_by_family) == {"normal", "lognormal", "uniform"}


def test_caps_are_ten_percent_of_the_range_beyond_the_extremes() -> None:
    x = np.array([2.0, 3.0, 2.5, 4.0, 3.2, 2.8, 3.6, 2.2, 3.3, 2.9, 3.1, 2.7])
    d = fit_dispersion("n", x)
    spread = x.max() - x.min()
    assert d.lower_cap == pytest.approx(x.min() - 0.1 * spread, rel=1e-15)
    assert d.upper_cap == pytest.approx(x.max() + 0.1 * spread, rel=1e-15)
    wider = fit_dispersion("n", x, cap_fraction=0.25)
    assert wider.upper_cap == pytest.approx(x.max() + 0.25 * spread, rel=1e-15)


@pytest.mark.parametrize("family", ["normal", "lognormal"])
def test_draws_respect_caps_and_follow_the_truncated_distribution(family: str) -> None:
    # 12 tests: the fitted distribution has a good deal of mass beyond the caps
    x = np.random.default_rng(31).lognormal(0.5, 0.3, 12)
    d = fit_dispersion("n", x, families=[family])
    assert d.family == family
    assert 1.0 - d.truncated_mass() > 0.01  # the caps do cut the distribution
    draws = d.sample(50_000, np.random.default_rng(32))
    assert draws.min() >= d.lower_cap and draws.max() <= d.upper_cap
    assert stats.kstest(draws, d.cdf).pvalue > P_MIN
    # the untruncated distribution is clearly not what is drawn
    assert stats.kstest(draws, d.frozen().cdf).pvalue < P_MIN


@pytest.mark.parametrize("caps", [(3.0, 4.0), (-4.0, -3.0), (-0.5, 0.7)])
def test_inverse_cdf_draws_in_either_tail(caps: tuple[float, float]) -> None:
    """Caps deep in one tail use the survival function (upper) or the CDF (lower)."""
    d = Dispersion(name="z", family="normal", parameters={"mean": 0.0, "std": 1.0},
                   lower_cap=caps[0], upper_cap=caps[1], gof=0.0)
    draws = d.sample(20_000, 41)
    assert draws.min() >= caps[0] and draws.max() <= caps[1]
    assert stats.kstest(draws, d.cdf).pvalue > P_MIN


def test_draws_are_reproducible_by_seed() -> None:
    d = fit_dispersion("Ck", np.random.default_rng(5).normal(1.5, 0.1, 30))
    assert np.array_equal(d.sample(100, 7), d.sample(100, np.random.default_rng(7)))
    assert not np.array_equal(d.sample(100, 7), d.sample(100, 8))


def test_text_names_family_parameters_and_caps() -> None:
    d = fit_dispersion("expopen", np.random.default_rng(6).lognormal(0.0, 0.6, 40))
    line = str(d)
    assert line.startswith("expopen: lognormal(mu_log=")
    assert f"{d.lower_cap:.6g}" in line and f"{d.upper_cap:.6g}" in line
    assert "AIC" in line and "normal" in line and "uniform" in line
    assert "p-value" in line  # says there is none


def test_lognormal_is_skipped_for_non_positive_values() -> None:
    d = fit_dispersion("bias", np.random.default_rng(8).normal(0.0, 1.0, 200))
    assert d.gof_by_family["lognormal"] == float("inf")
    assert d.family != "lognormal"


@pytest.mark.parametrize(("values", "message"), [
    ([1.0, np.nan, 2.0], "NaN"),
    ([1.0, np.inf, 2.0], "infinite"),
    ([1.0], "at least 2"),
    ([], "at least 2"),
    ([2.0, 2.0, 2.0], "equal"),
    ([[1.0, 2.0], [3.0, 4.0]], "1-D"),
])
def test_bad_samples_raise_a_clear_error(values: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        fit_dispersion("Ck", values)


def test_lognormal_only_with_a_negative_value_raises() -> None:
    with pytest.raises(ValueError, match="lognormal needs every test value > 0"):
        fit_dispersion("bias", [-1.0, 1.0, 2.0], families=["lognormal"])


def test_unknown_family_raises() -> None:
    with pytest.raises(ValueError, match="families must be among"):
        fit_dispersion("Ck", [1.0, 2.0, 3.0], families=["weibull"])


def test_caps_without_probability_raise() -> None:
    with pytest.raises(ValueError, match="no probability between the caps"):
        Dispersion(name="u", family="uniform", parameters={"lower": 0.0, "upper": 1.0},
                   lower_cap=2.0, upper_cap=3.0, gof=0.0)
