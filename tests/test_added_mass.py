"""Added mass (paper Eq. 1): its size, and the load it adds while a canopy grows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpas_ocp.effects import AddedMass, baseline_effects
from cpas_ocp.effects.added_mass import K_APPARENT, K_ENCLOSED, PROJECTED_RATIO
from cpas_ocp.flight_test import load_test
from cpas_ocp.model import Model
from cpas_ocp.parameters import param_name
from cpas_ocp.problems import load_problem
from cpas_ocp.simulate import simulate

FACTOR = 1.4


@pytest.fixture(scope="module")
def runs(drogue_folder):
    """The drogue phase simulated from the same start with and without added mass."""
    test = load_test(drogue_folder(1))
    problem = load_problem("drogue")
    truth = {**problem.truth, **{param_name("added_mass_factor", c.name): FACTOR
                                 for c in test.parachutes}}
    sim = problem.simulation
    out = {}
    for label, effects in (("rigid", baseline_effects()),
                           ("added", [*baseline_effects(), AddedMass()])):
        model = Model(test, effects)
        x0 = np.concatenate([sim["initial_state"][s.name] for s in model.states])
        traj = simulate(model, truth, x0, float(sim["t_begin"]), float(sim["t_end"]), 1e-3)
        pvec = model.parameter_vector(truth)
        cvec = np.array([traj.captures[c.name] for c in model.captures])
        q = np.asarray(model.quantities.map(len(traj.t))(traj.x.T, traj.t, pvec, cvec))
        out[label] = (traj, dict(zip(model.quantity_names, q, strict=True)))
    return test, truth, out


def test_added_mass_of_a_full_open_canopy(runs) -> None:
    test, truth, out = runs
    traj, q = out["added"]
    chute = test.parachutes[0]
    steady = traj.t > truth[param_name("t_start", chute.name, chute.stages[-1])] + 2.0
    cds = q[param_name("cds", chute.name)][steady]
    cds_o = truth[param_name("CdS", chute.name, chute.stages[-1])]
    diameter = PROJECTED_RATIO * chute.diameter * np.sqrt((cds + 1e-4) / cds_o)
    expected = (FACTOR * q["density"][steady] * math.pi * diameter**3
                * (K_ENCLOSED / 12 + K_APPARENT / 8))
    np.testing.assert_allclose(q[param_name("added_mass", chute.name)][steady], expected,
                               rtol=1e-9)
    # A 23 ft canopy at ~7 km carries on the order of 50 kg of air.
    assert 20.0 < float(np.median(expected)) < 150.0


def test_riser_gathers_the_air_while_the_canopy_grows(runs) -> None:
    test, truth, out = runs
    chute = test.parachutes[0]
    tension = param_name("tension", chute.name)
    t = out["added"][0].t
    for stage in chute.stages:
        t_i = truth[param_name("t_start", chute.name, stage)]
        rise = (t > t_i) & (t < t_i + 0.25)
        more = out["added"][1][tension][rise] - out["rigid"][1][tension][rise]
        # While the drag area grows, d(m_A)/dt V adds to the load: the peak is higher.
        assert np.max(out["added"][1][tension][rise]) > np.max(out["rigid"][1][tension][rise])
        assert np.max(more) > 0.02 * np.max(out["rigid"][1][tension][rise])
    # Long after the last stage the canopy no longer grows: the two loads differ only
    # by the slow deceleration of m_A (the trajectories differ slightly too).
    late = t > t[-1] - 2.0
    diff = np.abs(out["added"][1][tension][late] - out["rigid"][1][tension][late])
    assert np.max(diff) < 0.02 * np.mean(out["rigid"][1][tension][late])
