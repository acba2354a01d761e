"""An output that reads the state at another time, inside one that does too.

A load cell with fairlead friction reads the tension rate from the states half a
window either side of t (`ModelContext.at_time_offset`); a lag on that load cell
reports at t what the friction model gives at t - tau.  The inner offsets must
move with the lagged state: the lagged output must equal the unlagged friction
output at the state integrated back over tau (the lag's four RK4 steps).  And the
estimator's chained residuals and Jacobian (`chained_jacobians`) must agree with
the model's own expanded functions on that model.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_effects
from cpas_ocp.physics.effects import LoadCellFriction, SensorLag, baseline_effects
from cpas_ocp.physics.effects.sensor_lag import STEPS
from cpas_ocp.physics.integration import rk4
from cpas_ocp.physics.model import Model

LAG_S = 0.1


def _lagged_and_plain(folder) -> tuple[Model, Model]:
    test = load_test(folder)
    friction = [*baseline_effects(), LoadCellFriction()]
    lagged = spec_from_effects([*friction, SensorLag(kind="load_cell", name="lc_lag")])
    return lagged.model(test), spec_from_effects(friction).model(test)


def test_a_lag_moves_the_offsets_inside_the_output_it_delays(drogue_folder) -> None:
    lagged, plain = _lagged_and_plain(drogue_folder(1))
    values = {p.name: p.default for p in plain.parameters}
    values.update({"friction_loss[drogue1]": 0.15, "friction_loss[drogue2]": 0.15})
    p_plain = plain.parameter_vector(values)
    p_lagged = lagged.parameter_vector({**values, "lag[riser_drogue1]": LAG_S,
                                        "lag[riser_drogue2]": LAG_S})
    c = np.full(len(plain.captures), 40.0)
    x = np.array([0.0, 0.0, 2000.0, 3.0, -1.0, -60.0])
    t = 8.0  # inside the first stages' inflations, where the tension changes fast
    back = x
    for j in range(STEPS):  # the state at t - tau, as the lag takes it
        back = rk4(plain.rhs, back, t - j * LAG_S / STEPS, -LAG_S / STEPS, p_plain, c)
    expected = np.asarray(plain.outputs["riser_drogue1"](back, t - LAG_S, p_plain, c))
    now = np.asarray(plain.outputs["riser_drogue1"](x, t, p_plain, c))
    got = np.asarray(lagged.outputs["riser_drogue1"](x, t, p_lagged, c))
    assert abs(expected - now).max() > 1e-3 * abs(now).max()  # the lag changes the reading
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("lag", [0.0, LAG_S])
def test_chained_residuals_of_nested_offsets_match_the_model(drogue_folder, lag) -> None:
    test = load_test(drogue_folder(1))
    effects = [*baseline_effects(), LoadCellFriction(),
               SensorLag(kind="load_cell", name="lc_lag")]
    est = Estimator(test, spec_from_effects(effects), Settings(compile=False))
    z = est.initial_point()
    for name, value in (("lag[riser_drogue1]", lag), ("friction_loss[drogue1]", 0.1)):
        z = est.with_value(z, name, value)
    z = z * (1.0 + 1e-3 * np.random.default_rng(3).standard_normal(z.size))
    nlp = est.transcription
    r, jac = nlp.points.residual_jacobian(z)
    r_model = float(ca.Function("r", [nlp.z], [ca.sqrt(2 * nlp.objective)])(z))
    gradient = np.asarray(ca.Function("g", [nlp.z], [ca.gradient(nlp.objective, nlp.z)])(z))
    assert np.linalg.norm(r) == pytest.approx(r_model, rel=1e-12)
    np.testing.assert_allclose(jac.T @ r, gradient.ravel(), rtol=0,
                               atol=1e-12 * np.abs(gradient).max())
