"""Inelastic deployment load on the `drogue` problem: estimable, and missed without it.

Data are simulated with a 2,000 lbf (8,900 N) deployment load per Drogue from
its mortar fire to its inflation start (0.6 s each; the Drogues are mortared
0.1 s apart).  Through the vehicle's IMU (about 0.2 g for the pair) and the
riser load cells it is seen far above the noise, and it is independent of the
drag scale factors, which act only once a canopy inflates.

Tolerances come from the noise, through the reported covariance: the load
within 4 reported sigma of the truth, and a fit without the effect worse by
more than the chi-square 0.999 quantile for one parameter.
"""

from __future__ import annotations

import dataclasses

import pytest
from scipy.stats import chi2

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_block
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import DeploymentLoad, baseline_effects

pytestmark = pytest.mark.slow

LOAD_N = 8896.4  # 2,000 lbf


def _with_load() -> list:
    """The baseline set with the deployment load after the riser model."""
    effects = baseline_effects()
    riser = [e.name for e in effects].index("rigid_riser")
    return [*effects[:riser + 1], DeploymentLoad(), *effects[riser + 1:]]


@pytest.fixture(scope="module")
def loaded_test(tmp_path_factory):
    problem = load_problem("drogue")
    folder = tmp_path_factory.mktemp("deploy") / "test"
    truth = {**problem.truth, "deployment_load[drogue]": LOAD_N}
    simulate_problem(dataclasses.replace(problem, truth=truth), folder, 1, effects=_with_load())
    return load_test(folder)


def test_deployment_load_is_recovered_and_its_omission_costs_chi_square(loaded_test) -> None:
    est = Estimator(loaded_test, _with_load())
    fit = est.solve()
    assert fit.solver.success, fit.solver.status
    std = est.covariance(fit).std["deployment_load[drogue]"]
    assert std < 0.05 * LOAD_N
    assert abs(fit.parameters["deployment_load[drogue]"] - LOAD_N) < 4.0 * std
    without = Estimator(loaded_test, baseline_effects()).solve()
    assert without.solver.success, without.solver.status
    assert without.chi_square - fit.chi_square > chi2.ppf(0.999, 1)


def test_listing_it_after_the_load_cells_is_an_input_error(loaded_test) -> None:
    names = [*[e.name for e in baseline_effects()], "deployment_load"]
    spec = spec_from_block({"effects": names}, "model.json", loaded_test.path)
    with pytest.raises(InputError, match="before load_cell"):
        spec.model(loaded_test)
