"""Profile likelihood: a minimum at the fit, rising on both sides, and for a parameter the
model is nearly linear in, the covariance's interval.

On the `pilot` problem (seed 1) the drag area enters the trajectory almost
linearly over its 95 % interval: the profile's interval ends lie within
0.1 sigma of estimate -+ 1.96 sigma.  The check allows 0.3 sigma.  The fill
constant n is visibly asymmetric (its profile rises faster on the low side);
the check there is only that the interval brackets the estimate.

The pilot's expopen, which the problem holds at its true value 1, is
profiled by refitting with it freed and held at other values: the data
determine it, so its profile keeps the truth within the 95 % level of its
best point and rules out half and twice the truth.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference.profile_likelihood import THRESHOLD, held_profile, profile
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test

# The fit stops once the Gauss-Newton step would gain less than 0.01 in chi-square
# (`Settings.chi2_step_tol`), so a profile point may lie that much below the fit.
STOP_TOL = 0.01


@pytest.fixture(scope="module")
def pilot(problem_folder):
    est = Estimator(load_test(problem_folder("pilot", 1)))
    fit = est.solve()
    return est, fit, est.covariance(fit)


@pytest.mark.parametrize("base", ["CdS", "n"])
def test_profile_has_its_minimum_at_the_fit_and_rises_on_both_sides(pilot, base) -> None:
    est, fit, cov = pilot
    name = f"{base}[pilot1,stage1]"
    prof = profile(est, fit, cov, name, span=2.5, points=7)
    assert not prof.failures
    assert prof.values.size == 7
    assert np.all(prof.delta_chi_square > -STOP_TOL)
    centre = int(np.argmin(np.abs(prof.values - prof.estimate)))
    assert prof.delta_chi_square[centre] == 0.0
    assert np.all(np.diff(prof.delta_chi_square[centre:]) > 0)
    assert np.all(np.diff(prof.delta_chi_square[:centre + 1]) < 0)
    # 2.5 sigma out the profile must have passed the 95 % threshold on both sides.
    assert prof.delta_chi_square[0] > THRESHOLD and prof.delta_chi_square[-1] > THRESHOLD
    lo, hi = prof.interval()
    assert lo is not None and hi is not None and lo < prof.estimate < hi
    if base == "CdS":
        wlo, whi = prof.wald_interval()
        assert abs(lo - wlo) < 0.3 * prof.std and abs(hi - whi) < 0.3 * prof.std


def test_held_parameter_profile_keeps_the_truth_and_rules_out_the_far_values(pilot) -> None:
    _, fit, _ = pilot
    name = "expopen[pilot1,stage1]"
    assert name not in fit.free and fit.parameters[name] == 1.0
    grid = np.array([0.5, 0.9, 1.1, 1.5, 2.0])
    prof = held_profile(fit, spec_of_test(fit.test), name, grid)
    assert not prof.failures
    assert list(prof.values) == [0.5, 0.9, 1.0, 1.1, 1.5, 2.0]
    assert np.isnan(prof.std)
    # The held value is the fit itself; every point holds the parameter at its value.
    assert prof.delta_chi_square[2] == 0.0
    assert [p[name] for p in prof.parameters] == pytest.approx(list(prof.values), abs=1e-9)
    best = prof.delta_chi_square.min()
    assert prof.delta_chi_square[2] - best <= THRESHOLD
    assert prof.delta_chi_square[0] - best > THRESHOLD
    assert prof.delta_chi_square[-1] - best > THRESHOLD


def test_reconstruct_writes_profiles_and_refuses_an_unknown_name(problem_folder, tmp_path,
                                                                 capsys) -> None:
    folder = problem_folder("pilot", 1)
    code = main(["reconstruct", str(folder), "--out", str(tmp_path / "bad"),
                 "--profile", "CdS[nonesuch,stage1]"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--profile" in err[0] and "CdS[nonesuch" in err[0]
    assert not (tmp_path / "bad").exists()

    name = "CdS[pilot1,stage1]"
    code = main(["reconstruct", str(folder), "--out", str(tmp_path / "report"),
                 "--profile", name, "--profile-points", "5"])
    assert code == 0
    result = json.loads((tmp_path / "report" / "result.json").read_text())
    entry = result["profiles"][name]
    assert len(entry["values"]) == 5 and entry["interval95"][0] < entry["estimate"]
    assert (tmp_path / "report" / "profile_CdS_pilot1_stage1_.png").exists()
    assert "Profile likelihood" in (tmp_path / "report" / "report.md").read_text()
