"""What-if constraint studies on the `fbcp` problem (seed 1, as simulated).

At the truth a constraint costs little: the likelihood-ratio test is not
significant at the 0.1 % level.  Six reported sigma from the estimate it is
rejected, and, since the problem is nearly linear there, the cost and the
Lagrange multiplier agree with the covariance: chi-square rises by about
(d/sigma)^2 and d(chi^2)/d(value) is about 2 d / sigma^2 (each within 20 %).
An inequality the fit does not touch costs nothing and is not counted.
"""

from __future__ import annotations

import json

import pytest
from scipy.stats import chi2

from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.estimation import Estimator
from cpas_ocp.flight_test import load_test
from cpas_ocp.units import FT
from cpas_ocp.whatif import parse_constraint, what_if

NAME = "CdS[fbcp1,stage1]"


@pytest.fixture(scope="module")
def fbcp_study(problem_folder):
    folder = problem_folder("fbcp", 1)
    est = Estimator(load_test(folder))
    fit = est.solve()
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    return est, fit, est.covariance(fit), truth


def test_constraint_at_the_truth_is_not_rejected(fbcp_study) -> None:
    est, fit, cov, truth = fbcp_study
    result = what_if(est, fit, cov, [parse_constraint(f"{NAME} == {truth[NAME]!r}", est)])
    assert result.constrained.parameters[NAME] == pytest.approx(truth[NAME], rel=1e-9)
    assert result.active == [NAME]
    assert result.p_value > 1e-3, result.delta_chi_square


def test_constraint_far_from_the_estimate_is_rejected_with_a_large_multiplier(fbcp_study):
    est, fit, cov, _ = fbcp_study
    sigma = cov.std[NAME]
    offset = 6.0 * sigma
    result = what_if(est, fit, cov,
                     [parse_constraint(f"{NAME} == {fit.parameters[NAME] + offset!r}", est)])
    assert result.delta_chi_square > chi2.ppf(0.999, 1)
    assert result.delta_chi_square == pytest.approx(36.0, rel=0.2)
    assert result.constrained.sensitivities[NAME] == pytest.approx(2 * offset / sigma**2,
                                                                   rel=0.2)
    # The data that fight it: the canopy's own load cell or the IMU got worse, nothing better.
    worst = next(iter(result.channel_changes()))
    assert worst in ("riser_fbcp1.tension", "imu.load_factor")


def test_untouched_inequality_costs_nothing(fbcp_study) -> None:
    est, fit, cov, _ = fbcp_study
    limit = fit.parameters[NAME] + 10 * cov.std[NAME]
    result = what_if(est, fit, cov, [parse_constraint(f"{NAME} <= {limit!r}", est)])
    assert result.active == []
    assert result.p_value == 1.0
    assert abs(result.delta_chi_square) < 0.01


def test_units_and_mistakes(fbcp_study) -> None:
    est, _, _, _ = fbcp_study
    assert parse_constraint(f"{NAME} == 22 ft^2", est).value == pytest.approx(22 * FT**2)
    for text, field in (("CdS[fbcp1,stage1] = 2", "CdS[fbcp1,stage1] = 2"),
                        ("CdS[nope,stage1] == 2", "CdS[nope,stage1]"),
                        (f"{NAME} == 2 s", f"{NAME} unit"),
                        (f"{NAME} == 1e6", NAME)):
        with pytest.raises(InputError) as err:
            parse_constraint(text, est)
        assert err.value.field == field


def test_whatif_command_bad_expression_is_one_line_exit_2(problem_folder, capsys) -> None:
    code = main(["whatif", str(problem_folder("fbcp", 1)), "--constrain", "Ck[fbcp1] == 1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Ck[fbcp1]" in err, err
