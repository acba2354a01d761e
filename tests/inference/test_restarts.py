"""Restarts of a fit whose start time sits in a worse minimum (`cpas_ocp.inference.restarts`)."""

from __future__ import annotations

import pytest

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.restarts import misfit_start_times, restart_start_times
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

START = "t_start[pilot1,stage1]"


@pytest.fixture(scope="module")
def pilot(tmp_path_factory):
    """The `pilot` estimator, its fit from the reduction, and a fit started 0.2 s late."""
    folder = tmp_path_factory.mktemp("pilot") / "test"
    simulate_problem(load_problem("pilot"), folder, 1)
    est = Estimator(load_test(folder))
    fit = est.solve()
    late = est.solve(start=est.with_value(fit.z, START, fit.parameters[START] + 0.2))
    return est, fit, late


def test_a_fit_in_a_worse_minimum_of_its_start_time_is_restarted_into_the_better(pilot
                                                                                  ) -> None:
    """Started 0.2 s late, the pilot fit converges to another minimum (a later start with a
    faster fill), whose accelerometer residual in the inflation window exceeds the
    noise; moving the start time and re-solving finds the better minimum again."""
    est, fit, late = pilot
    assert late.chi_square > fit.chi_square + 10.0, "the late start found the same minimum"
    assert misfit_start_times(late) == [START]
    restarted, done = restart_start_times(est, late)
    assert [r.parameter for r in done] == [START] and done[0].shift_s < 0.0
    assert restarted.chi_square == pytest.approx(fit.chi_square, abs=0.1)
    assert "restarted with t_start[pilot1,stage1] moved by" in restarted.solver.start


def test_a_fit_that_meets_its_noise_is_not_restarted(pilot) -> None:
    est, fit, _ = pilot
    assert misfit_start_times(fit) == []
    same, done = restart_start_times(est, fit)
    assert same is fit and done == []
