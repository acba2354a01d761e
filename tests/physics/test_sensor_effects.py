"""Library sensor effects: additive bias and time lag, each simulated, then estimated.

Data come from the `fbcp` problem (4 s, 200 Hz IMU and load cells, 10 Hz GPS)
simulated with the effect; the reconstruction that includes the effect starts
from a zero bias or lag (the parameter's default, never the truth).  Tolerances
from the noise: each estimate within 4 reported sigma of the truth, a sigma at
most a tenth of the true value (the effect is really measured), chi-square per
degree of freedom within 5 of its own standard deviations of 1; and without
the effect chi-square is worse by far more than the likelihood-ratio threshold
for the added parameters.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import initial_state, simulate, simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import Effect, SensorBias, SensorLag, baseline_effects
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model

CASES = {
    "bias": ([SensorBias.imu(), SensorBias.load_cell()],
             {"bias[imu,load_factor]": 0.02, "bias[riser_fbcp1,tension]": 300.0,
              "bias[riser_fbcp2,tension]": -200.0}),
    "gps lag": ([SensorLag.gps()], {"lag[gps]": 0.12}),
}


def _simulated(folder, extra: list[Effect], values: dict[str, float]) -> FlightTest:
    problem = load_problem("fbcp")
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **values}), folder,
                     seed=1, effects=[*baseline_effects(), *extra])
    return load_test(folder)


@pytest.mark.slow  # a whole phase fitted
@pytest.mark.parametrize("case", list(CASES))
def test_sensor_effect_recovered_and_needed(case: str, tmp_path) -> None:
    extra, values = CASES[case]
    test = _simulated(tmp_path / "test", extra, values)
    est = Estimator(test, [*baseline_effects(), *extra])
    assert all(est.guess[n] == 0.0 for n in values)
    fit = est.solve(progress=False)
    assert fit.solver.success, fit.solver.status
    std = est.covariance(fit).std
    for name, true in values.items():
        assert abs(fit.parameters[name] - true) < 4 * std[name], name
        assert std[name] < abs(true) / 10, name
    assert abs(fit.chi_square / fit.dof - 1.0) < 5 * np.sqrt(2.0 / fit.dof)

    without = Estimator(test).solve(progress=False)
    assert without.chi_square - fit.chi_square > 10 * chi2.ppf(0.95, len(values))


def test_time_offset_matches_the_trajectory(tmp_path) -> None:
    """A 0.12 s GPS lag read mid-inflation equals the simulated state 0.12 s earlier."""
    lag = 0.12
    test = _simulated(tmp_path / "test", [SensorLag.gps()], {"lag[gps]": lag})
    problem = load_problem("fbcp")
    sim, truth = problem.simulation, {**problem.truth, "lag[gps]": lag}
    model = Model(test, [*baseline_effects(), SensorLag.gps()])
    step = 5e-4
    traj = simulate(model, truth, initial_state(model, sim), sim["t_begin"], sim["t_end"], step)
    p = model.parameter_vector(truth)
    c = np.array([traj.captures[cap.name] for cap in model.captures])
    now, then = round(0.95 / step), round((0.95 - lag) / step)  # fbcp1 starts at 0.80 s
    lagged = np.asarray(model.outputs["gps"](traj.x[now], traj.t[now], p, c)).ravel()
    earlier = np.concatenate([traj.x[then, model.state_slice("position")],
                              traj.x[then, model.state_slice("velocity")]])
    # GPS sigmas are 0.5 m and 0.1 m/s; the backward integration must be far inside them.
    assert np.max(np.abs(lagged[:3] - earlier[:3])) < 0.005
    assert np.max(np.abs(lagged[3:] - earlier[3:])) < 0.001
    # and the lag is really applied: the unlagged reading differs by about v * lag
    assert np.max(np.abs(traj.x[now, :3] - earlier[:3])) > 10.0


@pytest.mark.slow  # a whole phase fitted
def test_a_lag_is_refused_on_elastic_risers(problem_fit) -> None:
    """Integrated backwards, a damped riser mode grows as exp(zeta omega tau): a lag on a
    model with elastic risers is refused when the model is composed, and the diagnosis's
    score test of the elastic riser on a model with a lag says it does not apply."""
    from cpas_ocp.discrepancy.score_test import candidate_effects, score_test
    from cpas_ocp.errors import InputError
    from cpas_ocp.io.model_spec import spec_from_effects
    from cpas_ocp.physics.effects import with_elastic_risers

    fit, _, _ = problem_fit("fbcp", 1)
    both = spec_from_effects([*with_elastic_risers(baseline_effects()), SensorLag.gps()])
    with pytest.raises(InputError, match="cannot be combined with elastic risers"):
        both.model(fit.test)
    lagged = spec_from_effects([*baseline_effects(), SensorLag.gps()])
    fit = Estimator(fit.test, lagged).solve()
    result = score_test(fit, lagged, candidate_effects()["elastic_riser"])
    assert not result.tested
    assert "does not apply" in result.note and "elastic risers" in result.note
