"""A reconstruction's canopies carried into RocketPy (`cpas-ocp rocketpy`).

`rocket_steady` (seed 1: a drogue open from the record's start, a main mortared at
29.53 s, the altimeter alone) is reconstructed once; its canopies are built with
RocketPy's own classes and must carry the fit's numbers: the drag areas and their sigmas,
the drogue at apogee, the main at its deployment's height above the pad (against the
fitted trajectory, within the altimeter's noise), the lag from the deployment to the
fitted start.  The written script must build the same objects in a fresh interpreter.  A
report that is not a result is refused (exit 2).  The trigger rule is checked on an
imported synthetic log whose truth is known: the drogue's charge at apogee is "apogee",
the main's charge at 300 m above the pad is 300 m within a sample interval's descent.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp import api
from cpas_ocp.api.rocketpy_export import deployment_trigger, rocketpy_export
from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import MAIN_AGL_M, fly
from cpas_ocp.io.flight_test import load_test
from tests.rocket_logs import altimeter_log


@pytest.fixture(scope="module")
def steady(problem_folder, tmp_path_factory) -> tuple[api.Reconstruction, Path, Path]:
    """rocket_steady seed 1 reconstructed: the reconstruction, its test folder and its
    report folder."""
    folder = problem_folder("rocket_steady", 1)
    report = tmp_path_factory.mktemp("steady") / "report"
    rec = api.reconstruct(folder, out=report)
    assert rec.is_result
    return rec, folder, report


def test_the_parachutes_carry_the_fitted_drag_areas_triggers_and_lags(steady) -> None:
    pytest.importorskip("rocketpy")
    from rocketpy import Parachute
    from rocketpy.stochastic import StochasticParachute
    rec, folder, report = steady
    result = json.loads((report / "result.json").read_text())["parameters"]
    export = rocketpy_export(report, folder)
    assert export.as_dict() == rocketpy_export(rec).as_dict()  # the object and its report
    chutes = {p.name: p for p in export.parachutes()}
    stochastic = dict(zip(chutes, export.stochastic_parachutes(), strict=True))
    assert list(chutes) == ["drogue", "main"]
    for name, stage in (("drogue", "stage1"), ("main", "stage2")):
        cds = result[f"CdS[{name},{stage}]"]
        assert isinstance(chutes[name], Parachute)
        assert chutes[name].cd_s == cds["value"]
        assert isinstance(stochastic[name], StochasticParachute)
        assert stochastic[name].cd_s[:2] == (cds["value"], cds["std"])
    assert chutes["drogue"].trigger == "apogee" and chutes["drogue"].lag == 0.0
    fired = rec.fit.test.event("mortar_fire", "main").time
    start = result["t_start[main,stage2]"]
    assert chutes["main"].lag == pytest.approx(start["value"] - fired, abs=1e-12)
    assert stochastic["main"].lag[:2] == (chutes["main"].lag, start["std"])
    # The main's trigger: its height above the pad when its mortar fired, read off the
    # altimeter; the fitted trajectory's height then agrees within the altimeter's noise.
    altimeter_sigma = rec.fit.test.sensors_of("baro")[0].sigma["altitude"]
    fitted = np.interp(fired, rec.fit.t, rec.fit.quantities()["altitude"])
    height = fitted - rec.fit.test.atmosphere.elevation_m
    assert isinstance(chutes["main"].trigger, float)
    assert abs(chutes["main"].trigger - height) <= 3.0 * altimeter_sigma
    assert isinstance(stochastic["main"].create_object(), Parachute)  # a Monte Carlo draw


def test_the_written_script_builds_the_same_parachutes(steady, tmp_path, capsys) -> None:
    _, folder, report = steady
    out = tmp_path / "rocketpy"
    assert main(["rocketpy", str(report), "--test", str(folder), "--out", str(out)]) == 0
    assert "main" in capsys.readouterr().out
    numbers = json.loads((out / "parachutes.json").read_text())
    assert [p["trigger_kind"] for p in numbers["parachutes"]] == ["apogee", "height_agl_m"]
    pytest.importorskip("rocketpy")
    # The script run as a program (its own printout), then its objects' numbers.
    probe = ("import json, runpy, sys; s = runpy.run_path(sys.argv[1], run_name='__main__'); "
             "print(json.dumps([[p.name, p.cd_s, p.trigger, p.lag, "
             "list(s['STOCHASTIC_PARACHUTES'][k].cd_s[:2]), "
             "list(s['STOCHASTIC_PARACHUTES'][k].lag[:2])] for k, p in "
             "s['PARACHUTES'].items()]))")
    done = subprocess.run([sys.executable, "-c", probe, str(out / "parachutes.py")],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert "main: cd_s" in done.stdout
    built = json.loads(done.stdout.strip().splitlines()[-1])
    assert built == [[p["name"], p["cd_s_m2"], p["trigger"], p["lag_s"],
                      [p["cd_s_m2"], p["cd_s_std_m2"]], [p["lag_s"], p["lag_std_s"]]]
                     for p in numbers["parachutes"]]


def test_a_report_that_is_not_a_result_is_refused(steady, tmp_path, capsys) -> None:
    _, folder, report = steady
    refused = tmp_path / "refused"
    shutil.copytree(report, refused)
    result = json.loads((refused / "result.json").read_text())
    problem = "chi-square/dof = 14.2: beyond the 10 any honest reading of the noise allows"
    result["claim"].update(result=False, verdict="not a result", problems=[problem])
    (refused / "result.json").write_text(json.dumps(result))
    out = tmp_path / "out"
    assert main(["rocketpy", str(refused), "--test", str(folder), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "claim.result" in err and "is not: " + problem in err
    assert not out.exists()
    other = tmp_path / "other"
    shutil.copytree(folder, other)
    manifest = json.loads((other / "manifest.json").read_text())
    (other / "manifest.json").write_text(json.dumps({**manifest, "name": "another_test"}))
    assert main(["rocketpy", str(report), "--test", str(other), "--out", str(out)]) == 2
    assert "it is that of 'rocket_steady-seed1'" in capsys.readouterr().err


def test_an_imported_log_s_drogue_fires_at_apogee_and_its_main_at_its_height(tmp_path) -> None:
    """The synthetic log at 10 Hz (drogue's charge at apogee, main's at 300 m above the pad):
    the main's height is what the vehicle's was at the first sample after its charge, 300 m
    less at most one sample interval's descent, within the altimeter's noise."""
    rate_hz = 10.0
    test = load_test(altimeter_log(tmp_path, rate_hz, still_air=True))
    assert deployment_trigger(test, {}, "drogue")[0] == "apogee"
    height, fired, _ = deployment_trigger(test, {}, "main")
    truth = fly(thrust_n=1600.0, drogue_delay_s=0.0)
    speed = abs(np.interp(truth.events["main"], truth.t, truth.v))
    noise = test.sensors_of("baro")[0].sigma["altitude"]
    assert isinstance(height, float) and fired == pytest.approx(truth.events["main"],
                                                                abs=1.0 / rate_hz)
    assert MAIN_AGL_M - speed / rate_hz - 3.0 * noise <= height <= MAIN_AGL_M + 3.0 * noise
