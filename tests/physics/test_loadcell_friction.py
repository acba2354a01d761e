"""Fairlead friction: load cells read low in a rise and high in a decay; estimable on `fbcp`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import initial_state, model_outputs, simulate, simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import LoadCellFriction, baseline_effects
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name
from tests.conftest import START_GUESS_OFFSET_S, offset_events

FRICTION = 0.10  # a tenth of the pull lost in a fast rise


def test_reading_is_low_in_the_rise_and_high_in_the_decay(problem_folder) -> None:
    """On the truth trajectory: reading / tension is 1 - phi at the steep rise, above 1 while
    the over-inflation peak decays, and 1 once steady."""
    test = load_test(problem_folder("fbcp", 1))
    problem = load_problem("fbcp")
    model = Model(test, [*baseline_effects(), LoadCellFriction()])
    truth = {**problem.truth, **{param_name("friction_loss", c.name): FRICTION
                                 for c in test.parachutes}}
    sim = problem.simulation
    traj = simulate(model, truth, initial_state(model, sim), float(sim["t_begin"]),
                    float(sim["t_end"]), 1e-3)
    q = model.quantities_along(traj.t, traj.x, truth, traj.captures)
    sensor = test.sensors_of("load_cell")[0]
    reading = model_outputs(model, traj, truth, sensor.name, traj.t).ravel()
    tension = q[param_name("tension", sensor.parachute)]
    # The calibration gain k_P / s_stage of the single stage, without friction.
    gain = (truth[param_name("loadcell_scale", sensor.parachute)]
            / truth[param_name("drag_scale", "stage1")])
    loaded = tension > 5e3
    ratio = reading[loaded] / (gain * tension[loaded])
    assert ratio.min() == pytest.approx(1.0 - FRICTION, abs=0.01)
    assert ratio.max() > 1.0 + 0.3 * FRICTION
    assert ratio[-1] == pytest.approx(1.0, abs=1e-3)


@pytest.fixture(scope="module")
def friction_fits(tmp_path_factory):
    """fbcp seed 1 made with friction, events 0.3 s off; fitted with it, and without it
    from the full fit's estimate (the nested model of a likelihood-ratio test)."""
    problem = load_problem("fbcp")
    chutes = [c["name"] for c in problem.manifest["parachutes"]]
    truth = {**problem.truth, **{param_name("friction_loss", c): FRICTION for c in chutes}}
    full = [*baseline_effects(), LoadCellFriction()]
    root = tmp_path_factory.mktemp("friction")
    simulate_problem(dataclasses.replace(problem, truth=truth), root / "sim", 1, effects=full)
    test = load_test(offset_events(root / "sim", root / "test", START_GUESS_OFFSET_S))
    est = Estimator(test, full)
    fit = est.solve()
    start = {n: v for n, v in fit.parameters.items() if not n.startswith("friction_loss")}
    without = Estimator(test, baseline_effects(), Settings(guess=start)).solve()
    return truth, fit, est.covariance(fit), without


@pytest.mark.slow  # a whole phase fitted
def test_friction_recovered_and_needed(friction_fits) -> None:
    truth, fit, cov, without = friction_fits
    assert fit.solver.success
    assert abs(fit.chi_square / fit.dof - 1.0) < 5 * np.sqrt(2.0 / fit.dof)
    for name in (n for n in fit.free if n.startswith("friction_loss")):
        z = (fit.parameters[name] - truth[name]) / cov.std[name]
        assert abs(z) < 4.0, f"{name}: {z:.2f} sigma"
        assert cov.std[name] < FRICTION / 3, name  # the data resolve it
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    assert m2 < chi2.ppf(0.999, dof), f"Mahalanobis^2 {m2:.1f} on {dof} dof"
    # Without the effect: rejected by the likelihood ratio for its two parameters.
    delta = without.chi_square - fit.chi_square
    assert delta > chi2.ppf(0.999, 2), f"delta chi-square {delta:.1f}"
