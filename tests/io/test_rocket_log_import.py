"""One import command for rocketry logs: Altus Metrum, CATS and a column-mapped CSV.

The package's seeded example flight (`cpas_ocp.io.example_flight`: boost, coast,
drogue at apogee, main at 300 m, touchdown on ground 7 m above the pad, vertical
point-mass physics) is written as each flight computer would log it.
The import must find the flight events (from the log's states, or detected
from the accelerometer and the altimeter's ejection pulses) within two
sample intervals of the truth, detect touchdown, and write a loadable test
folder; a log ending before touchdown ends the phase at its end.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import (  # the flight and its truth, for the other tests too
    A_NOISE,
    CDS,
    GROUND_M,
    H_TABLE,
    P_TABLE,
    RATE_HZ,
    SITE,
    Flight,
    card,
    fly,
    sample_time,
    sensor_readings,
    write_altus,
)
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.atmosphere import pressure_altitude
from cpas_ocp.physics.units import G0

DT = 1.0 / RATE_HZ


@pytest.fixture(scope="module")
def flight() -> Flight:
    return fly()


CARD = card()


def _card(tmp_path: Path) -> Path:
    path = tmp_path / "card.json"
    path.write_text(json.dumps(CARD))
    return path


# --- the three layouts -------------------------------------------------------------------

def write_cats(flight: Flight, folder: Path, seed: int, unit_s: float = 1.0) -> None:
    """A CATS Configurator export: two IMUs whose axial axis is -x, two barometers, the
    flight states, GNSS at 1 Hz; time stamps from lift-off in units of `unit_s` (1: s,
    0.001: ms as the raw log counts)."""
    folder.mkdir()
    p, a = sensor_readings(flight, seed)
    rng = np.random.default_rng(seed + 10)
    imu, baro = [], []
    for k, t in enumerate(flight.t):
        for i in range(2):
            imu.append((round(t / unit_s, 3), f"IMU{i}", -(a[k] + G0) + rng.normal(0, 0.1),
                        rng.normal(0, A_NOISE), rng.normal(0, A_NOISE), 0.0, 0.0, 0.0))
            baro.append((round(t / unit_s, 3), f"BARO{i}", 25.0, p[k] + rng.normal(0, 1.0)))
    pd.DataFrame(imu, columns=["ts", "id", "Ax", "Ay", "Az", "Gx", "Gy", "Gz"]).to_csv(
        folder / "imu.csv", index=False)
    pd.DataFrame(baro, columns=["ts", "id", "T", "P"]).to_csv(folder / "baro.csv", index=False)
    ev = flight.events
    pd.DataFrame({"ts": np.array([-5.0, 0.0, ev["coast"], ev["drogue"], ev["main"],
                                  ev["landed"] + 3]) / unit_s,
                  "state": [2, 3, 4, 5, 6, 7]}).to_csv(folder / "flightStates.csv", index=False)
    fixes = flight.t[np.isclose(flight.t % 1.0, 0.0, atol=1e-6)]
    pd.DataFrame({"ts": fixes / unit_s, "latitude": 32.94 + 1e-5 * np.arange(fixes.size),
                  "longitude": -106.9, "satellites": 9}).to_csv(folder / "gnssInfo.csv",
                                                                index=False)
    (folder / "voltageInfo.csv").write_text("No data recorded")


COLUMN_MAP = {
    "recorder": "Acme altimeter",
    "time": {"column": "t_ms", "unit": "ms"},
    "pressure": {"column": "press_hPa", "unit": "hPa"},
    "acceleration": {"axes": {"x": "ax_g", "y": "ay_g", "z": "az_g"}, "axis": "auto",
                     "unit": "g"},
    "gnss": {"latitude": "lat", "longitude": "lon"},
}


def write_mapped(flight: Flight, path: Path, seed: int, end_s: float | None = None) -> None:
    """Another computer's log: time in ms, pressure in hPa, a three-axis accelerometer in g
    whose axial axis is -y, latitude/longitude only (1 Hz, blank between fixes), no flight
    states; cut at `end_s` where given."""
    p, a = sensor_readings(flight, seed)
    rng = np.random.default_rng(seed + 20)
    n = flight.t.size
    fix = np.isclose(flight.t % 1.0, 0.0, atol=1e-6)
    table = pd.DataFrame({
        "t_ms": np.round(1e3 * flight.t).astype(int),
        "press_hPa": np.round(p / 100.0, 2),
        "ax_g": np.round(rng.normal(0, A_NOISE, n) / G0, 4),
        "ay_g": np.round(-(a + G0) / G0, 4),
        "az_g": np.round(rng.normal(0, A_NOISE, n) / G0, 4),
        "lat": np.where(fix, 32.94 + 1e-5 * flight.t, np.nan),
        "lon": np.where(fix, -106.9 + 2e-5 * flight.t, np.nan)})
    if end_s is not None:
        table = table[flight.t <= end_s]
    table.to_csv(path, index=False, float_format="%.7g")


# --- the tests ---------------------------------------------------------------------------

def _import(args: list[str], out: Path) -> dict:
    assert main([*args, "--out", str(out)]) == 0
    load_test(out)
    return json.loads((out / "import.json").read_text())


def test_column_mapped_log_imports_with_detected_events(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No flight states: boost, burnout and both ejection charges are detected within two
    samples of the truth (the charges in the first sample that shows them), touchdown on
    ground 7 m above the pad within a few samples, the axial axis found as -y."""
    write_mapped(flight, tmp_path / "log.csv", seed=1)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    report = _import(["import", str(tmp_path / "log.csv"), "--columns",
                      str(tmp_path / "map.json"), "--card", str(_card(tmp_path))],
                     tmp_path / "test")
    events = report["flight_events"]
    for name in ("boost", "coast", "drogue", "main"):
        truth = sample_time(flight, flight.events[name])
        assert abs(events[name]["time_s"] - truth) <= 2 * DT + 1e-9, name
        assert events[name]["sigma_s"] <= 2 * DT + 1e-9, name
        # The stated sigma covers the error (a sigma too small to hold it would mislead the
        # start-time prior built from it).
        assert abs(events[name]["time_s"] - truth) <= 3 * events[name]["sigma_s"] + 1e-9, name
    assert abs(events["landed"]["time_s"] - flight.events["landed"]) <= 5 * DT
    # Apogee: the altitude's top, flat within the noise for a second or so.
    assert abs(events["apogee"]["time_s"] - flight.events["apogee"]) <= \
        max(3 * events["apogee"]["sigma_s"], 0.5)
    assert report["recorder"] == "Acme altimeter"
    assert "axial accelerometer axis: -y" in report["notes"]
    # The ground 7 m above the pad, in pressure altitude (the hot day reads it a little low).
    [landing] = [n for n in report["notes"] if n.startswith("touchdown at")]
    expected = float(pressure_altitude(np.interp(GROUND_M, H_TABLE, P_TABLE))
                     - pressure_altitude(SITE.pressure_pa))
    assert float(landing.split(", ")[1].split(" m")[0]) == pytest.approx(expected, abs=0.3)
    test = load_test(tmp_path / "test")
    assert test.t_start == pytest.approx(events["drogue"]["time_s"])
    assert test.t_end == pytest.approx(events["landed"]["time_s"] - 0.5)
    charge = test.event("mortar_fire", "main")
    assert charge.sigma == pytest.approx(events["main"]["sigma_s"], abs=1e-3)
    # The main's snatch, a second after its charge, is reported as its opening's peak;
    # with the accelerometer's samples in the folder it is not fitted as the fill's end.
    assert report["events_s"]["main full open"] == pytest.approx(
        sample_time(flight, flight.events["main"] + 1.0))
    assert test.event("full_open", "main") is None
    assert "flight events:" in capsys.readouterr().out


@pytest.mark.parametrize("unit_s", [1.0, 1e-3])
def test_cats_export_imports_with_its_states(flight: Flight, tmp_path: Path,
                                             unit_s: float) -> None:
    write_cats(flight, tmp_path / "flight-log-export", seed=2, unit_s=unit_s)
    report = _import(["import", str(tmp_path / "flight-log-export"), "--format", "cats",
                      "--card", str(_card(tmp_path))], tmp_path / "test")
    events = report["flight_events"]
    for name in ("boost", "coast", "drogue", "main"):
        assert events[name]["source"] == "flight state"
        assert events[name]["time_s"] == pytest.approx(flight.events[name], abs=1e-3)
    # The CATS touchdown state comes 3 s late: touchdown is detected, not taken from it.
    assert abs(events["landed"]["time_s"] - flight.events["landed"]) <= 5 * DT
    assert "axial accelerometer axis: -x" in report["notes"]
    assert report["recorder"] == "CATS flight computer"


def test_altus_log_labels_keeps_real_samples_and_detects_touchdown(
        flight: Flight, tmp_path: Path) -> None:
    """The AltOS export: labelled from its name and serial, the GPS record's repeating rows
    dropped but no real 100 Hz sample that repeats its neighbour's readings, and
    touchdown detected on ground 7 m above the pad (not AltOS's late landed state, nor the
    log's end)."""
    path = tmp_path / "telemega-serial-1234-flight-0002.csv"
    copies, chance = write_altus(flight, path, seed=3)
    report = _import(["import-altus", str(path), "--card", str(_card(tmp_path))],
                     tmp_path / "test")
    assert report["recorder"] == "TeleMega serial 1234"
    assert report["dropped"]["repeated_sensor_rows"] == copies + chance
    text = path.read_text().splitlines()
    rows = pd.DataFrame([r.split(",")[7:9] for r in text[1:]], dtype=float)
    equal_pairs = int((rows.diff() == 0).all(axis=1).sum())
    # Real samples repeating pressure and acceleration (not the speed): kept.
    assert equal_pairs > 2 * (copies + chance)
    events = report["flight_events"]
    assert abs(events["landed"]["time_s"] - flight.events["landed"]) <= 5 * DT
    assert events["main"]["time_s"] == pytest.approx(sample_time(flight, flight.events["main"]))
    # The same log through --format altus gives the same folder.
    again = _import(["import", str(path), "--format", "altus", "--card",
                     str(_card(tmp_path))], tmp_path / "again")
    assert again["events_s"] == report["events_s"]


def test_log_ending_before_touchdown_ends_the_phase_at_its_end(flight: Flight,
                                                              tmp_path: Path) -> None:
    end = flight.events["landed"] - 5.0
    write_mapped(flight, tmp_path / "log.csv", seed=4, end_s=end)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    report = _import(["import", str(tmp_path / "log.csv"), "--columns",
                      str(tmp_path / "map.json"), "--card", str(_card(tmp_path))],
                     tmp_path / "test")
    assert "landed" not in report["flight_events"]
    assert any("the log ends at" in n for n in report["notes"])
    assert report["phase_s"][1] == pytest.approx(sample_time(flight, end) - 0.5, abs=DT)


@pytest.mark.parametrize("change, field", [
    ({"pressure": {"column": "p", "unit": "hPa"}}, "pressure.column"),
    ({"pressure": {"column": "press_hPa", "unit": "inHg"}}, "pressure.unit"),
    ({"acceleration": {"axes": {"x": "ax_g", "y": "ay_g"}, "axis": "-z", "unit": "g"}},
     "acceleration.axis"),
    ({"time": {"column": "t_ms"}}, "time.unit"),
    ({"altitude": {"column": "press_hPa", "unit": "m"}}, "pressure/altitude"),
])
def test_column_map_errors_are_one_line(flight: Flight, tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str], change: dict,
                                        field: str) -> None:
    write_mapped(flight, tmp_path / "log.csv", seed=5, end_s=5.0)
    (tmp_path / "map.json").write_text(json.dumps({**COLUMN_MAP, **change}))
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(_card(tmp_path)), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert str(tmp_path / "map.json") in err[0] and f": {field}" in err[0]
    assert not (tmp_path / "test").exists()


@pytest.mark.parametrize(("pressure", "field"), [
    ("", "pressure"),  # a log without barometer readings: the log is named, not the card
    ("0", "line 4, press_hPa"),  # a pressure of zero has no pressure altitude
    ("-863.0", "line 4, press_hPa"),
])
def test_a_log_without_valid_pressures_is_one_line(flight: Flight, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str],
                                                  pressure: str, field: str) -> None:
    write_mapped(flight, tmp_path / "log.csv", seed=5)
    table = pd.read_csv(tmp_path / "log.csv", dtype=str, keep_default_na=False)
    if pressure:
        table.loc[2, "press_hPa"] = pressure
    else:
        table["press_hPa"] = ""
    table.to_csv(tmp_path / "log.csv", index=False)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(_card(tmp_path)), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: {tmp_path / 'log.csv'}: {field}:")
    assert not (tmp_path / "test").exists()


@pytest.mark.parametrize(("deployments", "expected"), [
    (("drogue", "drogue"), "deploys an earlier one too"),  # two openings, one event
    (("drogue", "landed"), "got 'landed'"),  # touchdown deploys nothing
])
def test_a_card_deploying_at_no_single_event_is_one_line(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        deployments: tuple[str, str], expected: str) -> None:
    write_mapped(flight, tmp_path / "log.csv", seed=5)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    card = json.loads(json.dumps(CARD))
    for chute, deployment in zip(card["parachutes"], deployments, strict=True):
        chute["deployment"] = deployment
    (tmp_path / "card.json").write_text(json.dumps(card))
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(tmp_path / "card.json"), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: {tmp_path / 'card.json'}: parachutes[1].deployment:")
    assert expected in err[0] and "landed," not in err[0] and "landed)" not in err[0]
    assert not (tmp_path / "test").exists()


def test_state_values_that_name_no_state_are_refused_not_ignored(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A state column mapped without `names` whose values are no flight state's name (a
    logger's numeric codes) is a mistake the user can mend with a `names` map: one line
    naming the map's field and the values the column holds, exit 2, nothing written."""
    write_mapped(flight, tmp_path / "log.csv", seed=5)
    table = pd.read_csv(tmp_path / "log.csv")
    table["mode"] = np.where(table["t_ms"] < 0, 1, 3)
    table.to_csv(tmp_path / "log.csv", index=False, float_format="%.7g")
    (tmp_path / "map.json").write_text(json.dumps({**COLUMN_MAP, "state": {"column": "mode"}}))
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(_card(tmp_path)), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: {tmp_path / 'map.json'}: state.column:")
    assert "'1', '3'" in err[0] and "names" in err[0]
    assert not (tmp_path / "test").exists()


def test_unknown_format_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "log.csv").write_text("a,b\n1,2\n")
    code = main(["import", str(tmp_path / "log.csv"), "--format", "eggtimer", "--card",
                 "prometheus", "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--format" in err[0] and "cats" in err[0]


def _import_layout(layout: str, flight: Flight, tmp_path: Path) -> Path:
    """The flight written in `layout` (altus, cats or a column-mapped CSV) and imported with
    one command into tmp_path/test."""
    _import(layout_arguments(layout, flight, tmp_path), tmp_path / "test")
    return tmp_path / "test"


def layout_arguments(layout: str, flight: Flight, tmp_path: Path) -> list[str]:
    """The flight written in `layout` (altus, cats or a column-mapped CSV) under tmp_path
    with its card: the `import` command's arguments, less its output folder."""
    card = str(_card(tmp_path))
    if layout == "altus":
        write_altus(flight, tmp_path / "telemega-serial-1234-flight-0002.csv", seed=3)
        args = ["import", str(tmp_path / "telemega-serial-1234-flight-0002.csv"),
                "--format", "altus"]
    elif layout == "cats":
        write_cats(flight, tmp_path / "flight-log-export", seed=2)
        args = ["import", str(tmp_path / "flight-log-export"), "--format", "cats"]
    else:
        write_mapped(flight, tmp_path / "log.csv", seed=1)
        (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
        args = ["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json")]
    return [*args, "--card", card]


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["columns", "cats", "altus"])
def test_imported_log_reconstructs(flight: Flight, tmp_path: Path, layout: str) -> None:
    """The folder imported from each layout reconstructs.  The generator's canopies
    fill by a linear ramp of drag area, not the model's finite-mass inflation, so the fit
    is judged by convergence (a SolverFailure would raise), a chi-square per degree of
    freedom within the noise (below 1 here: the altimeter's sigma floor of 0.3 m is above
    the generator's 2 Pa, 0.2 m) and steady drag areas within 1 % of the truth: under
    each open canopy the known mass and density fix the drag area by the descent rate,
    whatever the opening's model."""
    from cpas_ocp.estimation.estimator import Estimator

    est = Estimator(load_test(_import_layout(layout, flight, tmp_path)))
    fit = est.solve()
    cov = est.covariance(fit)
    assert 0.1 < fit.chi_square / fit.dof < 1.5
    for name, chute, stage in (("drogue", "drogue", "stage1"), ("main", "main", "stage2")):
        key = f"CdS[{chute},{stage}]"
        assert fit.parameters[key] == pytest.approx(CDS[name], rel=0.01), key
        assert np.isfinite(cov.std[key]) and cov.std[key] < 0.01 * CDS[name]


def test_column_map_with_altitude_states_and_gnss_altitude(flight: Flight,
                                                           tmp_path: Path) -> None:
    """A logger writing height above the pad in feet (the map's offset adds the pad's
    pressure altitude), its own state codes, and GNSS with altitude (ft) and velocities:
    the states give the events, the GNSS altitude is fitted with the lapse rate, the fixes
    are placed east/north/up about the pad, and the folder has no accelerometer."""
    from cpas_ocp.io.column_map import load_column_map, read_mapped_log
    from cpas_ocp.io.flight_record import enu_about
    from cpas_ocp.physics.units import FACTORS

    p, _ = sensor_readings(flight, seed=6)
    pad = float(pressure_altitude(SITE.pressure_pa))
    ft = FACTORS["length"]["ft"]
    fix = np.isclose(flight.t % 1.0, 0.0, atol=1e-6)
    ev = flight.events
    code = np.select([flight.t >= ev["main"], flight.t >= ev["drogue"],
                      flight.t >= ev["coast"], flight.t >= 0.0], [6, 5, 4, 3], 2)
    rng = np.random.default_rng(7)
    pd.DataFrame({
        "time": flight.t, "agl_ft": np.round((pressure_altitude(p) - pad) / ft, 2),
        "mode": code,
        "lat": np.where(fix, 32.94 + 1e-5 * flight.t, np.nan),
        "lon": np.where(fix, -106.9, np.nan),
        "gps_ft": np.where(fix, (SITE.elevation_m + flight.h + rng.normal(0, 2.0, flight.t.size))
                           / ft, np.nan),
        "ve": np.where(fix, 2.0, np.nan), "vn": np.where(fix, 0.5, np.nan),
    }).to_csv(tmp_path / "log.csv", index=False, float_format="%.8g")
    column_map = {
        "time": {"column": "time", "unit": "s"},
        "altitude": {"column": "agl_ft", "unit": "ft", "offset": pad / ft},
        "gnss": {"latitude": "lat", "longitude": "lon",
                 "altitude": {"column": "gps_ft", "unit": "ft"},
                 "velocity": {"east": "ve", "north": "vn", "unit": "m/s"}},
        "state": {"column": "mode", "names": {"3": "boost", "4": "coast", "5": "drogue",
                                              "6": "main"}},
    }
    (tmp_path / "map.json").write_text(json.dumps(column_map))
    record = read_mapped_log(tmp_path / "log.csv", load_column_map(tmp_path / "map.json"),
                             "map.json")
    assert record.states == pytest.approx({k: sample_time(flight, ev[k])
                                           for k in ("boost", "coast", "drogue", "main")})
    assert record.samples["pressure"].iloc[0] == pytest.approx(SITE.pressure_pa, abs=10.0)
    assert record.gnss["v_east"].iloc[0] == pytest.approx(2.0)
    enu = enu_about(record.gnss)
    assert enu["north"].iloc[-1] == pytest.approx(1e-5 * np.pi / 180 * 6371008.8
                                                  * (flight.t[fix][-1] - flight.t[fix][0]),
                                                  rel=1e-6)
    assert enu["up"].abs().max() > 500.0
    card = {**CARD, "site": {**CARD["site"], "lapse_rate": "gps"}}
    (tmp_path / "card.json").write_text(json.dumps(card))
    report = _import(["import", str(tmp_path / "log.csv"), "--columns",
                      str(tmp_path / "map.json"), "--card", str(tmp_path / "card.json")],
                     tmp_path / "test")
    assert report["flight_events"]["main"]["source"] == "flight state"
    # The GPS altitudes are fitted to within their 2 m noise (over 650 m of height the
    # lapse rate itself moves the fit by about a metre only: not determined here).
    assert report["lapse_fit"]["residual_sigma_m"] == pytest.approx(2.0, rel=0.3)
    assert report["samples"]["gps_altitude.csv"] > 40
    assert any("no accelerometer" in n for n in report["notes"])


def test_cats_export_without_its_imu_file_is_one_line(flight: Flight, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    write_cats(flight, tmp_path / "export", seed=8)
    (tmp_path / "export" / "imu.csv").unlink()
    code = main(["import", str(tmp_path / "export"), "--format", "cats", "--card",
                 str(_card(tmp_path)), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "imu.csv" in err[0]


@pytest.fixture(scope="module")
def cats_export(flight: Flight, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cats") / "export"
    write_cats(flight, folder, seed=9)
    return folder


# A damaged cell of a CATS export: (file, line, column, text) and what the one line names.
DAMAGED_CATS = {
    "an overflowing pressure": ("baro.csv", 3000, "P", "1e308", "line 3000, P"),
    "an infinite pressure": ("baro.csv", 3000, "P", "inf", "line 3000, P"),
    "an infinite flight state": ("flightStates.csv", 4, "state", "inf", "line 4, state"),
    "an overflowing acceleration": ("imu.csv", 3000, "Ax", "-1e308", "line 3000, Ax"),
    "a time stamp that is text": ("imu.csv", 3000, "ts", "x", "line 3000, ts"),
    "an infinite time stamp": ("baro.csv", 3000, "ts", "inf", "line 3000, ts"),
}


@pytest.mark.parametrize("case", list(DAMAGED_CATS))
def test_a_damaged_cats_cell_is_one_line(case: str, cats_export: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A cell no sensor can read (1e308, inf, text) is one line naming the file, its line
    and column, exit 2, no folder: never an overflow inside the reader (a state of inf)."""
    file, line, column, text, named = DAMAGED_CATS[case]
    shutil.copytree(cats_export, tmp_path / "export")
    lines = (tmp_path / "export" / file).read_text().splitlines()
    cells = lines[line - 1].split(",")
    cells[lines[0].split(",").index(column)] = text
    lines[line - 1] = ",".join(cells)
    (tmp_path / "export" / file).write_text("\n".join(lines) + "\n")
    code = main(["import", str(tmp_path / "export"), "--format", "cats", "--card",
                 str(_card(tmp_path)), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert file in err[0] and named in err[0], err
    assert not (tmp_path / "test").exists()


def test_a_cats_export_read_as_data_despite_glitches(cats_export: Path, tmp_path: Path) -> None:
    """Time stamps out of order, a negative one, a blank reading and a state code that is
    no state are data a real export may hold: read, not refused."""
    shutil.copytree(cats_export, tmp_path / "export")
    imu = (tmp_path / "export" / "imu.csv").read_text().splitlines()
    imu[3000:3100] = imu[3000:3100][::-1]
    imu[10] = "-7.5" + imu[10][imu[10].index(","):]
    (tmp_path / "export" / "imu.csv").write_text("\n".join(imu) + "\n")
    baro = (tmp_path / "export" / "baro.csv").read_text().splitlines()
    baro[2000] = baro[2000].rsplit(",", 1)[0] + ",nan"
    (tmp_path / "export" / "baro.csv").write_text("\n".join(baro) + "\n")
    states = (tmp_path / "export" / "flightStates.csv").read_text().splitlines()
    states.insert(2, "1.5,4.5")
    (tmp_path / "export" / "flightStates.csv").write_text("\n".join(states) + "\n")
    _import(["import", str(tmp_path / "export"), "--format", "cats", "--card",
             str(_card(tmp_path))], tmp_path / "test")


PROMETHEUS = Path(__file__).resolve().parents[3] / "shared" / "data" / "prometheus-2022"


@pytest.mark.parametrize("log_name", ["telemega-serial-6583-flight-0003.csv",
                                      "telemetrum-serial-5115-flight-0001.csv"])
def test_prometheus_events_are_found_with_the_states_hidden(log_name: str) -> None:
    """The real logs read as if their computer had logged no states: the main's charge (the
    TeleMega's pressure pulse; on the TeleMetrum only the snatch, with its 1 s lag as
    sigma) within three sigmas of the state AltOS logged (its own sigma 0.1 s added), the
    drogue's within the drogue window of it, touchdown before AltOS's late landed state."""
    from cpas_ocp.io.altus_metrum import read_altus_log
    from cpas_ocp.io.flight_events import DROGUE_WINDOW_S, detect_events

    if not (PROMETHEUS / log_name).is_file():
        pytest.skip(f"the Prometheus flight logs are not at {PROMETHEUS}")
    record = read_altus_log(PROMETHEUS / log_name).record()
    events, _ = detect_events(record.samples)
    main_ = events["main"]
    assert abs(main_.time - record.states["main"]) <= 3.0 * main_.sigma + 0.1
    assert abs(events["drogue"].time - record.states["drogue"]) <= DROGUE_WINDOW_S
    assert record.states["main"] < events["landed"].time < record.states["landed"]


def test_flight_with_a_card_whose_log_does_not_exist_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`cpas-ocp flight CARD` where the card's log is not in its data folder: exit 2, one
    line naming the card file and the log's path, nothing written."""
    card = {**CARD, "data": {"folder": "logs", "logs": ["flight.csv"], "columns": COLUMN_MAP}}
    (tmp_path / "logs").mkdir()
    (tmp_path / "card.json").write_text(json.dumps(card))
    code = main(["flight", str(tmp_path / "card.json"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert str(tmp_path / "card.json") in err[0], err
    assert str(tmp_path / "logs" / "flight.csv") in err[0], err
    assert not (tmp_path / "out").exists()
