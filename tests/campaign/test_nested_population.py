"""A test's canopies as one observation: the population's spread split into the test's and the
canopy's (`campaign/nested_population.py`), recovered from estimates drawn from the model
itself, and used by `cpas-ocp population` where the campaign kept the covariances between a
test's canopies (`benchmarks/studies/test_nested_coverage.py` scores the intervals over
many campaigns)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign.nested_population import NestedData, NestedModel, fit_nested
from cpas_ocp.campaign.population_model import PopulationData, fit_population
from cpas_ocp.campaign.population_study import population_groups
from cpas_ocp.cli import main
from tests.campaign.test_population_covariates import NAMES, campaign_rows

MEAN = np.log(np.array([2.0, 1.3]))


def draw_tests(seed: int, tests: int, tau_test: tuple[float, float],
               tau_canopy: tuple[float, float], noise: float = 0.03, rho: float = -0.9
               ) -> NestedData:
    """`tests` tests of two canopies, two parameters (log CdS, log Ck): each test's shared
    effect drawn with `tau_test`, each canopy's own with `tau_canopy`, and estimation noise
    `noise` (times a factor in [0.7, 1.4]) with the two canopies' CdS correlated `rho`."""
    rng = np.random.default_rng(seed)
    ys, Vs, Xs, openings = [], [], [], []
    for t in range(tests):
        sd = noise * rng.uniform(0.7, 1.4, (2, 2))
        V = np.diag(sd.reshape(-1) ** 2)
        V[0, 2] = V[2, 0] = rho * sd[0, 0] * sd[1, 0]
        shared = np.array(tau_test) * rng.standard_normal(2)
        theta = np.array([MEAN + shared + np.array(tau_canopy) * rng.standard_normal(2)
                          for _ in range(2)])
        ys.append(theta.reshape(-1) + np.linalg.cholesky(V) @ rng.standard_normal(4))
        Vs.append(V)
        Xs.append(np.ones((2, 1)))
        openings.append((f"t{t} a", f"t{t} b"))
    return NestedData(("CdS", "Ck"), (True, True), ("intercept",),
                      tuple(f"t{t}" for t in range(tests)), tuple(openings), tuple(ys),
                      tuple(Vs), tuple(Xs))


@pytest.mark.parametrize("reml", [True, False])
def test_the_likelihood_s_gradient_is_its_derivative(reml: bool) -> None:
    """The gradient through both Omegas' parametrisations (full) against central
    differences of the log-likelihood."""
    model = NestedModel(draw_tests(1, 10, (0.05, 0.04), (0.0, 0.03)), full_omega=True,
                        reml=reml)
    theta = np.array([np.log(0.05), np.log(0.04), 0.3, np.log(0.02), np.log(0.03), -0.2])
    _, analytic = model.log_likelihood(theta)
    h = 1e-6
    numeric = [(model.log_likelihood(theta + h * e)[0]
                - model.log_likelihood(theta - h * e)[0]) / (2 * h) for e in np.eye(6)]
    assert np.allclose(analytic, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.parametrize("tau_test, tau_canopy", [((0.05, 0.04), (0.0, 0.0)),
                                                  ((0.0, 0.0), (0.05, 0.04))])
def test_a_large_campaign_puts_the_spread_where_it_is(tau_test, tau_canopy) -> None:
    """300 tests: the median and each level's tau within their 99.9 % intervals, and the
    level without spread has an interval reaching 0."""
    data = draw_tests(2, 300, tau_test, tau_canopy)
    fit = fit_nested(data, level=0.999)
    for j, name in enumerate(data.names):
        assert fit.coefficients[(name, "intercept")].covers(MEAN[j]), name
        assert fit.tau_test[name].covers(tau_test[j]), (name, fit.tau_test[name])
        assert fit.tau_canopy[name].covers(tau_canopy[j]), (name, fit.tau_canopy[name])
    empty = fit.tau_canopy if tau_canopy[0] == 0.0 else fit.tau_test
    assert all(iv.lower == 0.0 for iv in empty.values())


def test_anti_correlated_canopies_pin_the_median_that_single_openings_do_not() -> None:
    """Two canopies whose CdS are correlated -0.99 (a load cell's scale shared), each known
    to 8 %, a test-level spread of 3 %: the two canopies' mean is known to about 0.6 %, so
    the median's standard error, about sqrt((0.08^2 * 0.005 + 0.03^2) / 12) with 12
    tests, is about half what the openings taken apart give, sqrt((0.08^2 + 0.03^2) / 24).
    Over ten campaigns the median ratio of the interval widths is above 1.5."""
    ratios = []
    for seed in range(10):
        data = draw_tests(100 + seed, 12, (0.03, 0.03), (0.0, 0.0), noise=0.08 / 1.05,
                          rho=-0.99)
        apart = PopulationData(
            data.names, tuple(o for op in data.openings for o in op),
            np.concatenate([y.reshape(2, 2) for y in data.y]),
            np.concatenate([np.stack([v[:2, :2], v[2:, 2:]]) for v in data.V]),
            np.ones((24, 1)), ("intercept",), data.log)
        nested = fit_nested(data).coefficients[("CdS", "intercept")]
        alone = fit_population(apart, tau_intervals=False).coefficients[("CdS", "intercept")]
        ratios.append((alone.upper - alone.lower) / (nested.upper - nested.lower))
    assert np.median(ratios) > 1.5


def test_the_command_splits_the_spread_where_the_campaign_kept_the_cross_covariances(
        tmp_path, capsys) -> None:
    """`cpas-ocp population` on two Drogues per test: with the covariances between the
    canopies written, the text and population.csv carry the test-level and canopy-level
    taus; without them, a note says why they are not separated."""
    folder = tmp_path / "campaign"
    folder.mkdir()
    table, cov = campaign_rows(seed=21, tests=10, cross=-0.9)
    table.to_csv(folder / "parameters.csv", index=False)
    cov.to_csv(folder / "covariances.csv", index=False)
    out = tmp_path / "population"
    assert main(["population", str(folder), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "test-level and canopy-level spread (10 tests" in printed
    written = pd.read_csv(out / "population.csv")
    assert written.tau_test_upper.notna().all() and written.tau_canopy_upper.notna().all()
    assert "tau canopy" in (out / "report.html").read_text()
    within = cov[cov.name_a.str.slice(-11) == cov.name_b.str.slice(-11)]
    within.to_csv(folder / "covariances.csv", index=False)
    assert main(["population", str(folder), "--out", str(out)]) == 0
    assert "lacks the covariances between a test's canopies" in capsys.readouterr().out
    assert pd.read_csv(out / "population.csv").tau_test.isna().all()


def test_one_canopy_per_test_is_not_split() -> None:
    table, cov = campaign_rows(seed=22, cross=-0.5)
    lone = table[table.parachute == "d1"]
    (group,), _ = population_groups(lone, cov, "campaign", parameters=NAMES)
    assert group.nested is None and not any("test-level" in n for n in group.notes)
