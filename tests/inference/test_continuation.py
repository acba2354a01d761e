"""Stiff effects brought in by continuation when a direct start from the reduction fails."""

from __future__ import annotations

import dataclasses

import pytest

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.inference import continuation
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.physics.effects import ElasticRiser


@pytest.fixture(scope="module")
def elastic_fbcp(problem_folder):
    """The `fbcp` test and its manifest's model with elastic risers for the rigid ones
    (VM evaluation: a model structure no other test compiles)."""
    test = load_test(problem_folder("fbcp", 1))
    spec = spec_of_test(test)
    effects = tuple(ElasticRiser() if e.name == "rigid_riser" else e for e in spec.effects)
    return test, dataclasses.replace(spec, effects=effects)


def test_the_relaxed_model_puts_back_what_each_stiff_effect_replaces(elastic_fbcp) -> None:
    test, spec = elastic_fbcp
    relaxed = continuation.relaxed_spec(spec, test)
    assert relaxed is not None
    assert relaxed.effect_names == [
        "rigid_riser" if n == "elastic_riser" else n for n in spec.effect_names]
    assert continuation.relaxed_spec(spec_of_test(test), test) is None


@pytest.mark.slow
def test_a_failed_direct_start_goes_through_the_relaxed_fit(elastic_fbcp, monkeypatch) -> None:
    test, spec = elastic_fbcp
    # One iteration cannot converge from the reduction: the fit must take the other road.
    # (On this test both roads end at chi-square 2628.2 after 80 iterations of the full
    # model; the direct one is not re-run here for time.)
    monkeypatch.setattr(continuation, "DIRECT_ITERATIONS", 1)
    est = Estimator(test, spec, Settings(compile=False, grid_step=0.01))
    fit = continuation.solve(est)
    assert fit.solver.success and fit.solver.chi2_decrement is not None
    assert fit.solver.chi2_decrement < 0.01
    assert fit.solver.start.startswith("a fit with rigid_riser in place of elastic_riser")
    assert "failed (Maximum_Iterations_Exceeded after 1 iterations)" in fit.solver.start
    assert fit.model.effects == est.model.effects
