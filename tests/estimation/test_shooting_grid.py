"""The shooting grid chosen from the dynamics: fine over the openings wherever their start
times may go, coarse in steady descent, refined for a stiffer model built from a fit, and
the same estimate as the sensor-rate grid."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpas_ocp.estimation.estimator import Estimator, Settings, default_grid_step
from cpas_ocp.estimation.shooting_grid import _accuracy_levels, _nodes, _stability_levels
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.physics.effects.registry import BUILTIN


def test_nodes_take_the_longest_aligned_step_every_interval_allows() -> None:
    levels = np.array([0, 0, 2, 2, 2, 2, 2, 2, 1, 1, 3, 3])
    # Two fine steps; at 2 a step of 2 (2 is not a multiple of 4), at 4 one of 4, at 8 one
    # of 2 (level 1), at 10 one of 2 (10 is not a multiple of 8 or 4).
    assert _nodes(levels).tolist() == [0, 1, 2, 4, 8, 10, 12]


@pytest.fixture(scope="module")
def drogue_grids(problem_folder):
    """The `drogue` problem (seed 1): its estimator on the grid from the dynamics with that
    estimator's fit, and its estimator on the uniform sensor-rate grid."""
    test = load_test(problem_folder("drogue", 1))
    dynamic = Estimator(test)
    uniform = Estimator(test, settings=Settings(grid_step=default_grid_step(test)))
    return dynamic, dynamic.solve(), uniform


def test_the_grid_is_fine_where_the_openings_may_start(drogue_grids) -> None:
    dynamic, _, uniform = drogue_grids
    h = default_grid_step(dynamic.test)
    steps = np.diff(dynamic.t)
    assert len(dynamic.t) < 0.6 * len(uniform.t)
    assert steps.max() > 8 * h  # steady descent between the stages
    m = dynamic.model
    for cap in m.captures:
        prm = m.parameter(cap.time_parameter)
        inside = (dynamic.t[:-1] >= prm.lower - 2 * h) & (dynamic.t[1:] <= prm.upper + 2 * h)
        assert np.allclose(steps[inside], h), cap.time_parameter


@pytest.mark.slow  # a second fit of the whole phase, on the fine uniform grid
def test_both_grids_give_one_estimate(drogue_grids) -> None:
    """Each statistical stop ends within 0.01 in chi-square and 0.1 sigma of its grid's
    optimum; the two optima agree to 1e-5 in chi-square and 0.001 sigma (measured from a
    common start with Ipopt's own tolerance), so the fits agree to the stops' tolerance."""
    _, fit_d, uniform = drogue_grids
    fit_u = uniform.solve()
    cov = uniform.covariance(fit_u)
    shift = max(abs(fit_d.parameters[n] - fit_u.parameters[n]) / cov.std[n]
                for n in fit_u.free)
    assert shift < 0.2
    assert abs(fit_d.chi_square - fit_u.chi_square) < 0.02


def test_a_stiffer_model_refines_the_fits_grid_and_starts_on_its_motion(drogue_grids) -> None:
    """An elastic riser at its null point (25 Hz, critically damped: |lambda| = 157/s)
    built from the rigid fit: RK4 on the fit's 160 ms steps would blow up, so its grid is
    refined; the fit's motion carried onto the new nodes by the fit's own RK4 steps keeps
    every shooting gap of the fit's states closed."""
    dynamic, fit, _ = drogue_grids
    spec = spec_of_test(dynamic.test)
    riser = BUILTIN["elastic_riser"].build({}, spec.source, "elastic_riser")
    effects = tuple(riser if e.name == "rigid_riser" else e for e in spec.effects)
    null = riser.null_values(dynamic.test)
    extended = Estimator(dynamic.test, dataclasses.replace(spec, effects=effects),
                         Settings(nodes=fit.settings.nodes,
                                  interval_steps=fit.settings.interval_steps, compile=False,
                                  fixed=null))
    assert set(np.round(fit.t, 6)) <= set(np.round(extended.t, 6))
    assert np.max(np.diff(extended.t)) * 2 * np.pi * 25.0 <= 2.8  # RK4's stability limit
    assert np.max(np.diff(extended.t)) < np.max(np.diff(fit.t))
    rigid = Estimator(dynamic.test, spec, Settings(
        nodes=tuple(extended.t), interval_steps=extended.settings.interval_steps, compile=False))
    chi2, violation = rigid.evaluate(rigid.point_from(fit))
    assert violation < 1e-6
    assert chi2 == pytest.approx(fit.chi_square, abs=0.05)


def test_where_the_first_guess_simulation_blows_up_the_grid_stays_fine(problem_folder) -> None:
    """A candidate effect's first guesses may make the simulation diverge (NaN states, as an
    extension of a rocket-log fit did in `flight`): there the grid knows no time scale and
    keeps every lattice node, rather than failing or coarsening on NaN comparisons."""
    test = load_test(problem_folder("fbcp", 1))
    model = spec_of_test(test).model(test)
    values = {p.name: p.default for p in model.parameters}
    captures = {c.name: 50.0 for c in model.captures}
    h, n = 0.005, 64
    t = test.t_start + h * np.arange(n + 1)
    x = np.zeros((n + 1, model.nx))
    x[:, model.state_slice("position")] = [0.0, 0.0, 3000.0]
    x[:, model.state_slice("velocity")] = [0.0, 0.0, -50.0]
    x[n // 2:] = np.nan
    stability = _stability_levels(model, values, x, t, captures, h)
    accuracy = _accuracy_levels(model, values, x, t, captures, h)
    assert np.all(stability[n // 2:] == 0) and np.all(accuracy[n // 2:] == 0)
    nodes = _nodes(np.minimum(stability, accuracy))
    assert set(range(n // 2, n + 1)) <= set(nodes.tolist())
