"""A new physical effect is one class in one place: no edit of the model or the estimator.

The effect here, an accelerometer bias, lives only in this file.  Data are
simulated with it; the reconstruction that includes it recovers the bias and
fits to the noise, while the baseline reconstruction cannot explain the data.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from cpas_ocp.effects import Effect, baseline_effects
from cpas_ocp.estimation import Estimator, Settings
from cpas_ocp.flight_test import FlightTest, load_test
from cpas_ocp.model import ModelContext
from cpas_ocp.parameters import Parameter, param_name
from cpas_ocp.problems import load_problem
from cpas_ocp.simulate import simulate_problem

TRUE_BIAS = 0.03  # g; three times the IMU's per-sample noise


@dataclass(frozen=True)
class AccelerometerBias(Effect):
    """Constant additive bias b (g) on every IMU load-factor reading: y = |f|/g0 + b."""

    name: str = "accelerometer_bias"

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("imu_bias", s.name), "g", 0.0, -0.5, 0.5,
                          description="load-factor bias", scale=0.01)
                for s in test.sensors_of("imu_load_factor")]

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of("imu_load_factor"):
            ctx.y[s.name]["load_factor"] = (ctx.y[s.name]["load_factor"]
                                            + ctx.p[param_name("imu_bias", s.name)])


@pytest.fixture(scope="module")
def biased_test(tmp_path_factory: pytest.TempPathFactory) -> FlightTest:
    problem = load_problem("drogue")
    imu = next(s["name"] for s in problem.manifest["sensors"] if s["kind"] == "imu_load_factor")
    truth = {**problem.truth, param_name("imu_bias", imu): TRUE_BIAS}
    folder = tmp_path_factory.mktemp("biased") / "test"
    simulate_problem(dataclasses.replace(problem, truth=truth), folder, seed=3,
                     effects=[*baseline_effects(), AccelerometerBias()])
    return load_test(folder)


def test_plugin_effect_is_estimated_and_explains_the_data(biased_test: FlightTest) -> None:
    est = Estimator(biased_test, [*baseline_effects(), AccelerometerBias()])
    name = next(n for n in est.free if n.startswith("imu_bias["))
    assert est.guess[name] == 0.0  # the estimator starts from the default, not the truth
    fit = est.solve()
    std = est.covariance(fit).std[name]
    assert abs(fit.parameters[name] - TRUE_BIAS) < 4 * std
    assert std < TRUE_BIAS / 10
    assert abs(fit.chi_square / fit.dof - 1.0) < 5 * np.sqrt(2.0 / fit.dof)

    # The nested model without the bias, refitted from the full fit's estimate (the
    # usual start for a likelihood-ratio comparison).  From the reduction's guess the
    # misspecified baseline fit wanders: Gauss-Newton with 3-sigma systematic IMU
    # residuals ran 500 iterations without converging.
    start = {n: v for n, v in fit.parameters.items() if n != name}
    baseline = Estimator(biased_test, settings=Settings(guess=start)).solve()
    # Without the bias the model cannot fit the IMU: chi-square rises by far more than
    # the 1-parameter likelihood-ratio threshold (3.84 at 5 %).
    assert baseline.chi_square - fit.chi_square > 100.0
