"""Single-shot reconstruction of the simulated FBCP phase recovers the synthetic truth.

Two 7 ft FBCPs fill in about 0.13 s at 150 m/s, so the start, fill constant
and shape of each rise rest on some 25 samples per sensor at 200 Hz.  The
line-stretch events are 0.3 s off the truth; the initial guesses come from
the offline reduction, or, in the last test, the start times straight from
those events.

Tolerances come from the noise, through the reported covariance:
- jointly, the squared Mahalanobis distance of estimate from truth below the
  chi-square 0.999 quantile for its degrees of freedom;
- singly, every estimate within 4 reported standard deviations;
- the reported sigmas are small enough for those checks to mean something:
  drag areas to 5 %, over-inflation to 2 %, start times to 5 ms.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.estimation.estimator import STATISTICALLY_CONVERGED, Estimator, Settings
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.model import Model
from tests.conftest import (
    START_GUESS_OFFSET_S,
    assert_sigmas_resolve,
    assert_truth_within_noise,
    event_errors,
    offset_events,
)

pytestmark = pytest.mark.slow  # a recovery study: fits of a whole phase

SEEDS = [1, 2]
SIGMA_CEILING = {"CdS": 0.05, "Ck": 0.02}  # relative
START_SIGMA_CEILING_S = 0.005


@pytest.mark.parametrize("seed", SEEDS)
def test_fbcp_truth_recovered_within_the_noise(problem_fit, seed: int) -> None:
    fit, cov, truth = problem_fit("fbcp", seed)
    assert fit.solver.success, fit.solver.status
    # The 200 Hz sensors set the finest step, which the openings get.
    assert np.min(np.diff(fit.t)) == pytest.approx(0.005)
    assert event_errors(fit, truth) == pytest.approx(START_GUESS_OFFSET_S, abs=1e-6)
    assert abs(fit.chi_square / fit.dof - 1.0) < 5 * np.sqrt(2.0 / fit.dof)
    assert not cov.at_bound

    assert_sigmas_resolve(fit, cov, SIGMA_CEILING, START_SIGMA_CEILING_S)
    dof = assert_truth_within_noise(fit, cov, truth)
    assert dof == len(fit.free) - 1  # the load-cell scales' geometric mean is fixed


def test_fbcp_converges_from_the_observed_events(problem_folder, tmp_path) -> None:
    """Start times guessed at the (0.3 s off) events rather than the curve fit still converge.

    The same tolerances as above, on seed 1: the reduction's curve fit is a
    convenience, not what makes the estimation work.
    """
    folder = problem_folder("fbcp", 1)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    test = load_test(offset_events(folder, tmp_path / "test", START_GUESS_OFFSET_S))
    model = Model(test, baseline_effects())
    at_events = {p.name: p.default for p in model.parameters if p.name.startswith("t_start[")}
    est = Estimator(test, settings=Settings(guess=at_events))
    assert all(abs(est.guess[n] - truth[n]) == pytest.approx(START_GUESS_OFFSET_S)
               for n in at_events)
    fit = est.solve()
    assert fit.solver.status == STATISTICALLY_CONVERGED
    cov = est.covariance(fit)
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    assert m2 < chi2.ppf(0.999, dof), f"Mahalanobis^2 {m2:.1f} on {dof} dof"
