"""Every sensor of a test folder is fitted, or the user is told: a manifest without a model
block fits each sensor kind it has; a model block that predicts none of them is a one-line
error (exit 2), one that leaves some out is warned about; a misspelt sensor field or a
one-component table wind is refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test, unfitted_sensors


@pytest.fixture(scope="module")
def steady(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The altimeter-only `rocket_steady` log (seed 1)."""
    out = tmp_path_factory.mktemp("steady") / "test"
    assert main(["simulate", "rocket_steady", "--out", str(out), "--seed", "1"]) == 0
    return out


def _copy_with(folder: Path, dest: Path, change) -> Path:
    dest.mkdir()
    for f in folder.iterdir():
        (dest / f.name).write_bytes(f.read_bytes())
    m = json.loads((dest / "manifest.json").read_text())
    change(m)
    (dest / "manifest.json").write_text(json.dumps(m))
    return dest


def test_without_a_model_block_every_sensor_kind_is_fitted(steady: Path, tmp_path: Path) -> None:
    folder = _copy_with(steady, tmp_path / "t", lambda m: m.pop("model", None))
    test = load_test(folder)
    model = spec_of_test(test).model(test)
    assert {s.kind for s in test.sensors} == {"baro"}
    assert unfitted_sensors(test, model) == []
    assert "altitude" in model.sensor_channels["baro"]


def test_a_model_that_predicts_no_sensor_is_refused(steady: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    def gps_only(m: dict) -> None:
        m["model"] = {"effects": ["canopy_inflation", "forebody_drag", "rigid_riser", "gps"]}
    folder = _copy_with(steady, tmp_path / "t", gps_only)
    out = tmp_path / "out"
    assert main(["reconstruct", str(folder), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "manifest.json: model.effects:" in err[0] and "baro" in err[0]
    assert not out.exists()


def test_a_misspelt_sensor_field_is_refused(steady: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    folder = _copy_with(steady, tmp_path / "t",
                        lambda m: m["sensors"][0].update(sigma_relativ=0.01))
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "sensors[0]" in err and "sigma_relativ" in err


def test_a_table_wind_needs_both_components(steady: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    def one_wind(m: dict) -> None:
        m["atmosphere"] = {"model": "table", "file": "air.csv",
                           "columns": {"altitude": "m", "density": "kg/m^3",
                                       "wind_east": "m/s"}}
    folder = _copy_with(steady, tmp_path / "t", one_wind)
    (folder / "air.csv").write_text("altitude,density,wind_east\n0,1.2,3\n5000,0.7,5\n")
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "atmosphere.columns" in err and "wind_north" in err


def test_a_sensor_no_effect_predicts_is_warned_about(steady: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """A model that predicts some sensors but not all: the others are named as unfitted
    (the fit goes on with those it predicts) and the command line warns about them."""
    def with_gps(m: dict) -> None:
        m["sensors"].append({"name": "gps", "kind": "gps_altitude", "file": "gps.csv",
                             "columns": {"time": "s", "up": "m"},
                             "sigma": {"altitude": {"value": 5.0, "unit": "m"}}})
    folder = _copy_with(steady, tmp_path / "t", with_gps)
    baro = (folder / "baro.csv").read_text().splitlines()
    (folder / "gps.csv").write_text("\n".join(["time,up", *baro[1::20]]) + "\n")
    test = load_test(folder)
    assert unfitted_sensors(test, spec_of_test(test).model(test)) == ["gps"]
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "out")]) == 0
    assert "warning: no effect of the model predicts sensor(s) gps" in capsys.readouterr().err
