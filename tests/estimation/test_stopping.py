"""The statistical stop's finishing step: a nearly feasible iterate is finished by one
Gauss-Newton step, and the answer is the one the solver would have reached."""

from __future__ import annotations

import numpy as np
import pytest

from cpas_ocp.estimation.estimator import (
    STATISTICALLY_CONVERGED,
    STOP_CONSTRAINT_TOL,
    Estimator,
    Settings,
)
from cpas_ocp.estimation.gauss_newton import gauss_newton
from cpas_ocp.io.flight_test import load_test

pytestmark = pytest.mark.slow


def test_the_finishing_step_gives_the_same_estimate_feasibly(problem_folder) -> None:
    """On `fbcp` the statistical stop, with its finishing steps, ends no later than Ipopt's
    own convergence, at a feasible point, on the estimate Ipopt converges to."""
    test = load_test(problem_folder("fbcp", 1))
    before = Estimator(test, settings=Settings(chi2_step_tol=None)).solve()
    est = Estimator(test, settings=Settings())
    after = est.solve()
    assert after.solver.status == STATISTICALLY_CONVERGED
    assert after.solver.iterations <= before.solver.iterations
    # Where it stopped is feasible (the shooting gaps closed), and the reported objective
    # is that point's own.
    chi2, violation = est.evaluate(after.z)
    assert violation <= STOP_CONSTRAINT_TOL
    assert chi2 == pytest.approx(after.chi_square, rel=1e-12)
    assert 2.0 * after.solver.objective == pytest.approx(chi2, rel=1e-12)
    # The stop claims every parameter within 0.1 sigma of the optimum Ipopt converges to.
    cov = est.covariance(after)
    shift = np.array([(after.parameters[n] - before.parameters[n]) / cov.std[n]
                      for n in after.free])
    assert np.max(np.abs(shift)) < 0.2
    assert abs(after.chi_square - before.chi_square) < 0.02


def test_the_stop_counts_what_closing_the_gaps_costs(problem_folder) -> None:
    """On `drogue` the run once stopped at an iterate whose gaps were all below
    STOP_CONSTRAINT_TOL yet worth 3.8 in chi-square (0.1 mm/s per interval adds up over
    2,000 intervals): it reported a chi-square below the feasible optimum.  Now the stop
    ends where closing the gaps changes chi-square by less than its tolerance, and agrees
    with the solver's own convergence."""
    test = load_test(problem_folder("drogue", 1))
    reference = Estimator(test, settings=Settings(chi2_step_tol=None)).solve()
    est = Estimator(test, settings=Settings())
    fit = est.solve()
    assert fit.solver.status == STATISTICALLY_CONVERGED
    step = gauss_newton(est.linearisations.linearise(fit.z))
    assert abs(step.restoration) <= est.settings.chi2_step_tol
    # Both are at the optimum to within the stop's tolerance (0.01) and the solver's own
    # (objective changes below 1e-9 relative over 5 iterations, ~1e-5 here).
    assert abs(fit.chi_square - reference.chi_square) < 0.02
