"""Stage-dependent sensor gains hand over smoothly through each stage's rise."""

from __future__ import annotations

import numpy as np
import pytest

from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name

SPEED = 100.0  # m/s, the captured start airspeed of every stage in this test


@pytest.fixture(scope="module")
def model_and_truth(drogue_folder):
    test = load_test(drogue_folder(1))
    return Model(test, baseline_effects()), load_problem("drogue").truth


def _quantities(model: Model, truth: dict[str, float], t: np.ndarray) -> dict[str, np.ndarray]:
    pvec = model.parameter_vector(truth)
    cvec = np.full(len(model.captures), SPEED)
    vals = np.asarray(model.quantities.map(len(t))(np.zeros((model.nx, len(t))), t, pvec, cvec))
    return dict(zip(model.quantity_names, vals, strict=True))


def test_weights_partition_unity_and_hand_over_through_the_rise(model_and_truth) -> None:
    model, truth = model_and_truth
    chute = model.test.parachutes[0]
    t = np.linspace(model.test.t_start, model.test.t_end, 4001)
    q = _quantities(model, truth, t)
    weights = [q[param_name("stage_weight", chute.name, s)] for s in chute.stages]
    np.testing.assert_allclose(np.sum(weights, axis=0), 1.0, atol=1e-12)

    stage = chute.stages[2]
    t_i = truth[param_name("t_start", chute.name, stage)]
    rise = truth[param_name("n_p", chute.name, stage)] * chute.diameter / SPEED
    at = np.array([t_i - 0.01, t_i, t_i + rise / 2, t_i + rise, t_i + rise + 0.01])
    w = _quantities(model, truth, at)[param_name("stage_weight", chute.name, stage)]
    np.testing.assert_allclose(w, [0.0, 0.0, 0.5, 1.0, 1.0], atol=1e-12)


def test_weights_partition_unity_when_a_stage_starts_during_the_previous_rise(
        model_and_truth) -> None:
    model, truth = model_and_truth
    chute = model.test.parachutes[0]
    early = dict(truth)
    t2 = truth[param_name("t_start", chute.name, chute.stages[1])]
    rise2 = truth[param_name("n_p", chute.name, chute.stages[1])] * chute.diameter / SPEED
    early[param_name("t_start", chute.name, chute.stages[2])] = t2 + 0.3 * rise2
    t = np.linspace(t2 - 0.1, t2 + 2 * rise2, 2001)
    q = _quantities(model, early, t)
    weights = np.array([q[param_name("stage_weight", chute.name, s)] for s in chute.stages])
    np.testing.assert_allclose(weights.sum(axis=0), 1.0, atol=1e-12)
    assert np.all(weights >= -1e-12)


def test_loadcell_gain_moves_from_one_stage_scale_to_the_next(model_and_truth) -> None:
    model, truth = model_and_truth
    chute = model.test.parachutes[1]
    prev, stage = chute.stages[1], chute.stages[2]
    t_i = truth[param_name("t_start", chute.name, stage)]
    rise = truth[param_name("n_p", chute.name, stage)] * chute.diameter / SPEED
    t = np.linspace(t_i - 0.05, t_i + rise + 0.05, 801)
    gain = _quantities(model, truth, t)[param_name("loadcell_gain", chute.name)]
    k = truth[param_name("loadcell_scale", chute.name)]
    before = k / truth[param_name("drag_scale", prev)]
    after = k / truth[param_name("drag_scale", stage)]
    assert gain[0] == pytest.approx(before, rel=1e-12)
    assert gain[-1] == pytest.approx(after, rel=1e-12)
    # Monotone, and no step: the largest change between samples 1 ms apart is the
    # smoothstep's peak slope over the rise, not a jump at t_i.
    steps = np.diff(gain)
    assert np.all(np.sign(steps[np.abs(steps) > 0]) == np.sign(after - before))
    dt = t[1] - t[0]
    assert np.max(np.abs(steps)) <= abs(after - before) * (15 / 16) * 2 / rise * dt * 1.01
