"""What-if constraint studies on the `fbcp` problem (seed 1, as simulated).

At the truth a constraint costs little: the likelihood-ratio test is not
significant at the 0.1 % level.  Six reported sigma from the estimate it is
rejected, and, since the problem is nearly linear there, the cost and the
Lagrange multiplier agree with the covariance: chi-square rises by about
(d/sigma)^2 and d(chi^2)/d(value) is about 2 d / sigma^2 (each within 20 %).
An inequality the fit does not touch costs nothing and is not counted; one
the fit presses against is tested against the chi-bar-squared mixture
(half the chi-square tail for one inequality).

A limit on a derived quantity, the peak riser load, binds the whole
trajectory.  Where the data want the peak at X0 and it is held at X < X0, the
cost is close to quadratic in X0 - X, so the multiplier and the cost agree:
delta chi^2 ~ -d(chi^2)/dX (X0 - X) / 2 (within 20 %).
"""

from __future__ import annotations

import json

import pytest
from scipy.stats import chi2

from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference.whatif import parse_constraint, what_if
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.units import FT, LBF

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


def test_contradictory_constraints_are_refused(fbcp_study) -> None:
    """Two '==' on one parameter, '==' beside a bound, or bounds that cross: each is named;
    consistent one-sided bounds combine."""
    from cpas_ocp.inference.whatif import parameter_bounds

    est, _, _, _ = fbcp_study
    for texts in ((f"{NAME} == 2", f"{NAME} == 3"), (f"{NAME} == 2", f"{NAME} == 2"),
                  (f"{NAME} <= 5", f"{NAME} == 2"), (f"{NAME} <= 2", f"{NAME} >= 3")):
        with pytest.raises(InputError) as err:
            parameter_bounds([parse_constraint(t, est) for t in texts], est)
        assert err.value.field == texts[1], texts
    both = parameter_bounds([parse_constraint(f"{NAME} >= 2", est),
                             parse_constraint(f"{NAME} <= 3", est)], est)
    assert both[NAME] == (2.0, 3.0)


def test_whatif_command_bad_expression_is_one_line_exit_2(problem_folder, capsys) -> None:
    code = main(["whatif", str(problem_folder("fbcp", 1)), "--constrain", "Ck[fbcp1] == 1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Ck[fbcp1]" in err, err


def test_one_sided_constraint_is_tested_against_chi_bar_squared(fbcp_study) -> None:
    est, fit, cov, _ = fbcp_study
    limit = fit.parameters[NAME] - 2.0 * cov.std[NAME]
    result = what_if(est, fit, cov, [parse_constraint(f"{NAME} <= {limit!r}", est)])
    assert result.active == [NAME]
    assert result.delta_chi_square == pytest.approx(4.0, rel=0.2)
    assert result.p_value == pytest.approx(0.5 * chi2.sf(result.delta_chi_square, 1), rel=1e-9)


def test_peak_load_limit_binds_and_its_multiplier_matches_its_cost(fbcp_study) -> None:
    est, fit, cov, _ = fbcp_study
    peak = float(fit.quantities()["tension[fbcp1]"].max())
    limit_lbf = round(0.97 * peak / LBF)
    result = what_if(est, fit, cov, [parse_constraint(
        f"peak_load[fbcp1] <= {limit_lbf} lbf", est)])
    limit = limit_lbf * LBF
    assert result.active == ["peak_load[fbcp1]"]
    held = float(result.constrained.quantities()["tension[fbcp1]"].max())
    assert held <= limit * (1 + 1e-6) and held == pytest.approx(limit, rel=1e-4)
    sensitivity = result.constrained.sensitivities["peak_load[fbcp1]"]
    assert sensitivity < 0.0  # a higher limit would fit better
    assert result.delta_chi_square > 0.1
    assert result.delta_chi_square == pytest.approx(-sensitivity * (peak - limit) / 2, rel=0.2)


def test_peak_limit_above_the_peak_costs_nothing_and_mistakes_are_named(fbcp_study) -> None:
    est, fit, cov, _ = fbcp_study
    peak = float(fit.quantities()["tension[fbcp2]"].max())
    result = what_if(est, fit, cov, [parse_constraint(
        f"peak_load[fbcp2] <= {1.05 * peak / 1e3!r} kN", est)])
    assert result.active == [] and result.p_value == 1.0
    assert abs(result.delta_chi_square) < 0.01
    for text, field in (("peak_load[nope] <= 5000 lbf", "peak_load[nope]"),
                        ("peak_load[fbcp1] >= 5000 lbf", "peak_load[fbcp1]"),
                        ("peak_load[fbcp1] <= 5000 s", "peak_load[fbcp1] unit"),
                        ("peak_speed <= 3", "peak_speed")):
        with pytest.raises(InputError) as err:
            parse_constraint(text, est)
        assert err.value.field == field
