"""A wrong fit is never called a result: chi-square/dof beyond 10, a process beyond 5 sigma
of its prior and an undetermined drag area exit 4; chi-square/dof far below 1 says the
sigmas are overstated; parameters on bounds are flagged wherever printed; the worst window
of a slow channel is its worst."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import SensorResidual
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.diagnostics import MIN_WINDOW_SAMPLES, worst_windows
from cpas_ocp.inference.result_claim import (
    LOW_MISFIT,
    MAX_MISFIT,
    PROCESS_SIGMAS,
    Claim,
    check_drag_areas,
    process_departures,
    process_misfits,
)
from cpas_ocp.physics.parameters import Parameter
from cpas_ocp.reports.display_units import DisplayUnits
from cpas_ocp.reports.report_data import bound_flag, parameter_rows


def claim_of(chi_square: float, dof: int, **kwargs) -> Claim:
    """A claim with no held bounds, its tail probabilities those of chi^2_dof."""
    return Claim(chi_square, dof, float(chi2.sf(chi_square, dof)), [],
                 low_p_value=float(chi2.cdf(chi_square, dof)), **kwargs)


def scaled_sigmas(folder: Path, dest: Path, factor: float) -> Path:
    """A copy of a test folder with every sensor sigma multiplied by `factor`."""
    shutil.copytree(folder, dest)
    manifest = json.loads((dest / "manifest.json").read_text())
    for sensor in manifest["sensors"]:
        for sigma in sensor["sigma"].values():
            sigma["value"] *= factor
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return dest


# --- chi-square/dof beyond the noise --------------------------------------------------------

def test_a_chi_square_beyond_ten_per_dof_is_not_a_result_and_names_the_worst_sensor() -> None:
    claim = claim_of(2521.0 * 400, 400, worst_sensor="baro", worst_sensor_rms=50.2)
    assert claim.beyond_noise and not claim.is_result
    assert claim.verdict() == "NOT A RESULT"
    first = claim.problems()[0]
    assert "50.2 times their stated noise" in first
    assert "the model lacks an effect or the sigmas are wrong" in first
    assert "the worst sensor is baro" in first
    assert claim.as_dict()["result"] is False


def test_a_real_flights_misfit_below_ten_stays_a_warned_result() -> None:
    """Prometheus in still air (chi^2/dof 5.3) and as it was (6-9): a result, with a misfit."""
    for ratio in (5.31, 8.91, 0.999 * MAX_MISFIT):
        claim = claim_of(ratio * 1900, 1900, worst_sensor="baro", worst_sensor_rms=3.1)
        assert claim.is_result and not claim.fits_noise
        assert claim.verdict() == "a result, with a misfit"


# --- chi-square/dof far below 1 -------------------------------------------------------------

def test_a_chi_square_far_below_one_says_the_sigmas_are_overstated() -> None:
    claim = claim_of(0.096 * 600, 600)
    assert claim.is_result and claim.overstates_noise
    assert claim.verdict() == "a result, with overstated sigmas"
    line = claim.problems()[-1]
    assert "the stated sigmas are too large by about 1/sqrt(chi-square/dof) = 3.2" in line
    assert "the uncertainties are overstated" in line
    assert claim.headline().startswith("Uncertainties overstated.")


def test_a_chi_square_just_under_one_on_many_samples_is_not_called_overstated() -> None:
    """chi^2/dof 0.9 on 5000 dof lies far in the lower tail but overstates sigmas by 5 %:
    not said; 0.4 on 12 dof is chance (P = 0.036): not said either."""
    many = claim_of(0.9 * 5000, 5000)
    assert many.low_p_value < many.alpha and not many.overstates_noise
    few = claim_of(0.4 * 12, 12)
    assert few.ratio < LOW_MISFIT and not few.overstates_noise
    assert many.verdict() == few.verdict() == "a result"


# --- processes against their priors ---------------------------------------------------------

class _Knots:
    """An effect with process parameters: knots every 4 s with a prior of 1 m/s."""

    name = "wind_process"

    def __init__(self, n: int) -> None:
        self.n = n

    def process_priors(self, test: object) -> dict[str, tuple[float, float]]:
        return {f"wind_up[{k}]": (4.0 * k, 1.0) for k in range(self.n)}


def process_fit(knots: np.ndarray, innovations: np.ndarray) -> SimpleNamespace:
    """A fit holding only a process: its knot values (m/s) and standardised innovations."""
    names = [f"wind_up[{k}]" for k in range(knots.size)]
    t = 4.0 * np.arange(innovations.size)
    residual = SensorResidual("wind_process", "wind_up", t, np.zeros(t.size), innovations,
                              np.ones(t.size))
    model = SimpleNamespace(effects=[_Knots(knots.size)],
                            penalties=[("wind_process", "wind_up", t, None)],
                            parameter=lambda n: Parameter(n, "m/s", 0.0, -30.0, 30.0))
    return SimpleNamespace(model=model, test=None, free=names,
                           parameters=dict(zip(names, knots.tolist(), strict=True)),
                           residuals=[residual])


def test_a_knot_beyond_five_sigma_is_named_with_its_time_and_sigma() -> None:
    rng = np.random.default_rng(7)
    knots = rng.normal(0.0, 0.5, 30)
    knots[[12, 13]] = [-18.0, -21.0]
    departures = process_departures(process_fit(knots, rng.normal(0.0, 1.0, 30)))
    assert {d.name for d in departures if d.kind == "knot"} == {"wind_up[12]", "wind_up[13]"}
    claim = claim_of(1.2 * 900, 900, departures=departures)
    assert not claim.is_result
    text = claim.problems()[0]
    assert "wind_up[13] at t = 52.00 s is -21 m/s, -21.0 sigma of its prior" in text


def test_innovations_within_five_sigma_and_a_livelier_air_are_a_warned_result() -> None:
    """Prometheus's block: 50 innovations at normalised RMS 1.54 (P = 2e-7), knots within
    2.7 sigma: said as a misfit of the prior, not a departure."""
    rng = np.random.default_rng(11)
    innovations = rng.normal(0.0, 1.0, 50)
    innovations *= 1.54 / np.sqrt(np.mean(innovations**2))
    fit = process_fit(np.clip(rng.normal(0.0, 1.0, 50), -2.7, 2.7), innovations)
    assert np.max(np.abs(innovations)) < PROCESS_SIGMAS
    assert process_departures(fit) == []
    misfits = process_misfits(fit)
    assert len(misfits) == 1 and "livelier than its prior's sigma" in misfits[0]


def test_a_block_far_beyond_its_prior_departs_even_with_every_innovation_below_five() -> None:
    rng = np.random.default_rng(13)
    innovations = np.sign(rng.normal(size=40)) * rng.uniform(3.5, 4.9, 40)
    fit = process_fit(np.zeros(40), innovations)
    departures = process_departures(fit)
    assert [d.kind for d in departures] == ["block"]
    assert not claim_of(1.0 * 900, 900, departures=departures).is_result


# --- undetermined drag areas ----------------------------------------------------------------

def drag_fit(values: dict[str, float]) -> SimpleNamespace:
    """A fit of drag areas (m^2) bounded to [0.001, 2.1], the upper bound a guess."""
    prm = {n: Parameter(n, "m^2", 1.0, 0.001, 2.1, physical_lower=True) for n in values}
    return SimpleNamespace(model=SimpleNamespace(parameter=prm.__getitem__), free=list(values),
                           parameters=dict(values), chi_square=100.0, dof=100)


def test_a_drag_area_undetermined_by_its_covariance_is_not_a_result() -> None:
    names = ["CdS[a,s1]", "CdS[b,s1]", "CdS[c,s1]", "CdS[d,s1]", "n[b,s1]"]
    fit = drag_fit(dict(zip(names, [0.5, 0.093, 2.1, 0.4, 50.0], strict=True)))
    std = np.array([0.01, 0.2, 0.0, 0.05, 80.0])
    cov = Covariance(names, np.diag(std**2), ["CdS[c,s1]"], 1.0, undetermined=["CdS[d,s1]"])
    claim = check_drag_areas(claim_of(100.0, 100), fit, cov)
    found = claim.undetermined_drag_areas
    assert len(found) == 3 and not claim.is_result
    assert found[0].startswith("CdS[b,s1] = 0.093 m^2: its sigma 0.2 m^2 is larger")
    assert found[1].startswith("CdS[c,s1] = 2.1 m^2: it is on its guessed upper bound")
    assert found[2].startswith("CdS[d,s1] = 0.4 m^2: it lies in a combination")
    assert "the data do not determine the drag area CdS[b,s1]" in claim.problems()[0]
    # A sigma below the value but not after the misfit's scaling (chi^2/dof 9: x3).
    fit = drag_fit({"CdS[a,s1]": 0.5})
    fit.chi_square = 900.0
    cov = Covariance(["CdS[a,s1]"], np.array([[0.2**2]]), [], 9.0)
    assert check_drag_areas(claim_of(900.0, 100), fit, cov).undetermined_drag_areas


# --- bounds flagged --------------------------------------------------------------------------

def test_a_value_on_or_within_one_sigma_of_a_bound_is_flagged() -> None:
    """expopen = 6 printed as 6 ± 84 (6 its upper bound): flagged, as on its bound."""
    names = ["expopen[main,s2]", "n[main,s2]", "t_k[main,s2]"]
    prm = {"expopen[main,s2]": Parameter(names[0], "1", 1.0, 0.3, 6.0),
           "n[main,s2]": Parameter(names[1], "1", 8.0, 0.3, 60.0),
           "t_k[main,s2]": Parameter(names[2], "s", 0.3, 0.01, 3.0, physical_lower=True)}
    fit = SimpleNamespace(model=SimpleNamespace(parameter=prm.__getitem__, effects=()),
                          free=names,
                          parameters={names[0]: 5.9993, names[1]: 9.9, names[2]: 0.01},
                          guess={}, test=None)
    cov = Covariance(names, np.diag([84.0, 2.3, 0.0]) ** 2, [names[2]], 1.0)
    assert bound_flag(fit, cov, names[0]) == "within 1σ of its upper bound (6, guessed)"
    assert bound_flag(fit, cov, names[1]) == ""
    assert bound_flag(fit, cov, names[2]) == "on its lower bound (0.01, physical)"
    fit.parameters[names[0]] = 6.0
    assert bound_flag(fit, None, names[0]) == "on its upper bound (6, guessed)"
    rows = parameter_rows(fit, cov, DisplayUnits("si"))
    assert [r.flag for r in rows] == ["on its upper bound (6, guessed)", "",
                                      "on its lower bound (0.01, physical)"]


# --- the worst window ------------------------------------------------------------------------

def test_the_worst_window_of_a_slow_channel_is_at_least_its_whole_misfit() -> None:
    """A 1 Hz GNSS at normalised RMS 2.42 beside a 10 Hz altimeter that fits its noise: the
    worst window is the GNSS's, no better than its whole RMS, of enough samples."""
    rng = np.random.default_rng(3)
    t_baro = np.arange(0.0, 120.0, 0.1)
    baro = SensorResidual("baro", "altitude", t_baro, rng.normal(0.0, 1.0, t_baro.size),
                          np.zeros(t_baro.size), np.ones(t_baro.size))
    t_gps = np.arange(0.0, 120.0, 1.0)
    z = rng.normal(0.0, 1.0, t_gps.size)
    z *= 2.42 / np.sqrt(np.mean(z**2))
    gps = SensorResidual("gps", "up", t_gps, 3.0 * z, np.zeros(t_gps.size),
                         np.full(t_gps.size, 3.0))
    fit = SimpleNamespace(residuals=[baro, gps], pseudo_sensors=("events", "priors"))
    worst = worst_windows(fit, top=3)
    assert worst[0].sensor == "gps" and worst[0].normalised_rms >= 2.42
    assert all(w.samples >= MIN_WINDOW_SAMPLES for w in worst)
    gps_windows = [w for w in worst if w.sensor == "gps"]
    assert gps_windows[0].t1 - gps_windows[0].t0 >= (MIN_WINDOW_SAMPLES - 1) * 1.0


# --- real fits through the command line ------------------------------------------------------

@pytest.fixture(scope="module")
def steady_folder(problem_folder) -> Path:
    return problem_folder("rocket_steady", 1)


@pytest.mark.slow
def test_sigmas_four_times_too_small_exit_4_naming_the_sensor(steady_folder, tmp_path,
                                                              capsys) -> None:
    """rocket_steady, its right model, its altimeter's sigma stated 4x too small: chi^2/dof
    about 14 (0.9 x 16): not a result, exit 4; the report is written and says why."""
    test = scaled_sigmas(steady_folder, tmp_path / "tight", 0.25)
    assert main(["reconstruct", str(test), "--out", str(tmp_path / "out")]) == 4
    err = capsys.readouterr().err
    assert "beyond the 10 any honest reading of the noise allows" in err
    assert "the worst sensor is baro" in err
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["claim"]["result"] is False and result["claim"]["beyond_noise"] is True
    assert result["fit"]["chi_square_per_dof"] > MAX_MISFIT
    assert "**Not a result.**" in (tmp_path / "out" / "report.md").read_text()


@pytest.mark.slow
def test_sigmas_ten_times_too_large_warn_that_uncertainties_are_overstated(
        steady_folder, tmp_path, capsys) -> None:
    test = scaled_sigmas(steady_folder, tmp_path / "loose", 10.0)
    assert main(["reconstruct", str(test), "--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert "claim: a result, with overstated sigmas" in captured.out
    assert "the stated sigmas are too large by about" in captured.err
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["claim"]["overstates_noise"] is True
    assert result["fit"]["chi_square_per_dof"] < LOW_MISFIT
    assert "**Uncertainties overstated.**" in (tmp_path / "out" / "report.md").read_text()
    assert "Uncertainties overstated." in (tmp_path / "out" / "report.html").read_text()


@pytest.mark.slow
def test_a_parameter_on_a_guessed_bound_is_flagged_in_every_output(problem_folder, tmp_path,
                                                                   capsys) -> None:
    """rocket_gusts (seed 2) in still air, sigmas halved: the main's drag area ends on its
    guessed upper bound; every table says so, and the claim names the drag area."""
    test = scaled_sigmas(problem_folder("rocket_gusts", 2), tmp_path / "test", 0.5)
    out = tmp_path / "out"
    assert main(["reconstruct", str(test), "--out", str(out)]) == 4
    captured = capsys.readouterr()
    flag = "on its upper bound"
    line = next(s for s in captured.out.splitlines() if s.startswith("CdS[main,stage2]"))
    assert flag in line
    table = pd.read_csv(out / "parameters.csv").set_index("parameter")
    assert table.loc["CdS[main,stage2]", "bound"].startswith(flag)
    result = json.loads((out / "result.json").read_text())
    assert result["parameters"]["CdS[main,stage2]"]["bound"].startswith(flag)
    assert result["parameters"]["CdS[drogue,stage1]"]["bound"] is None
    report = (out / "report.md").read_text()
    assert any(flag in s for s in report.splitlines() if s.startswith("CdS[main,stage2]"))
    assert flag in (out / "report.html").read_text()
    assert any("drag area CdS[main,stage2]" in p for p in result["claim"]["problems"])
