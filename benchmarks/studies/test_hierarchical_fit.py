"""The hierarchical fit's limits and its estimate on three `fbcp` tests whose canopies' drag
areas are drawn from a population (median 2.0 m^2, tau 0.05 in log; the fits never see
the draws):

* a population far wider than the data's sigma (tau = 1) leaves each copy at its own
  test's estimate (within a tenth of that estimate's sigma);
* a population far narrower (tau = 1e-5) ties the copies into the joint fit's one shared
  drag area (the median within a tenth of the joint fit's sigma, which is about 0.1 %:
  each test fixes its two canopies' sum far better than either);
* tau estimated by the Laplace deviance: inside its search range, the fit a result (within
  the noise, nothing undetermined or at a bound), and the median's 95 % interval covers
  the population's median (one draw: a 5 % chance of a miss).

About three minutes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.hierarchical_fit import TAU_RANGE, hierarchical_fit
from cpas_ocp.inference.joint_fit import joint_fit
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

NAME = "CdS[fbcp,stage1]"


@pytest.fixture(scope="module")
def tests(tmp_path_factory):
    rng = np.random.default_rng(5)
    base = load_problem("fbcp")
    out = []
    for i in range(3):
        truth = dict(base.truth)
        for chute in ("fbcp1", "fbcp2"):
            truth[f"CdS[{chute},stage1]"] = float(2.0 * np.exp(0.05 * rng.standard_normal()))
        folder = tmp_path_factory.mktemp("hier") / f"t{i}"
        simulate_problem(dataclasses.replace(base, truth=truth), folder, 900 + i)
        (folder / "truth.json").unlink()
        out.append(load_test(folder))
    return out


@pytest.mark.slow
def test_a_wide_population_leaves_each_test_its_own_estimate(tests) -> None:
    fit = hierarchical_fit(tests, {"CdS": "type"}, tau={NAME: 1.0})
    pop = fit.estimate(NAME)
    for key, value in pop.copies.items():
        t, name = key.split(":", 1)
        own = fit.individual[int(t)].parameters[name]
        sigma = fit.individual_covariances[int(t)].std[name]
        assert abs(value - own) < 0.1 * sigma, (key, value, own, sigma)


@pytest.mark.slow
def test_a_narrow_population_is_the_joint_fit(tests) -> None:
    shared = joint_fit(tests, {"CdS": "type"}).estimate(NAME)
    pop = hierarchical_fit(tests, {"CdS": "type"}, tau={NAME: 1e-5}).estimate(NAME)
    assert abs(pop.median - shared.value) < 0.1 * shared.std
    assert max(pop.copies.values()) - min(pop.copies.values()) < 0.1 * shared.std


@pytest.mark.slow
def test_tau_estimated_and_the_median_covered(tests) -> None:
    fit = hierarchical_fit(tests, {"CdS": "type"})
    pop = fit.estimate(NAME)
    assert TAU_RANGE[0] < pop.tau < TAU_RANGE[1]
    assert fit.is_result, fit.problems
    assert pop.lower < 2.0 < pop.upper
