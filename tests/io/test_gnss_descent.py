"""A descent logged only by the GNSS, and a log whose files end at different times.

The seeded generator of `cpas_ocp/io/example_flight.py` flies the rocket; the
altimeter's file ends at apogee (or just after the drogue's charge) while a GNSS file,
fixes at 5 Hz with `GNSS_SIGMA_M` of seeded white noise on the true altitude, goes on to
the ground.  The import must read the descent in the GNSS altitude: touchdown, the
descent's drag area (within three of the sigmas it states of the truth), a
``gps_altitude`` series at a sigma from its own scatter (within the sampling error of a
robust sigma of that many fixes), and a note saying so; a reconstruction of that folder
must recover the canopy's drag area within two of its sigmas.  Each file is read over its
own span: an accelerometer that goes on reads the main's charge, the altimeter's last
samples hold the drogue's charge, not damage or the impact, and the GNSS's last fixes,
jumping as the receiver loses its lock, are never a charge.
"""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import (
    CDS,
    CDS_BODY,
    DRY_MASS,
    MASS,
    SITE,
    Flight,
    fly,
    sample_time,
    sensor_readings,
)
from cpas_ocp.io.flight_test import load_test
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, DT, write_mapped

GNSS_SIGMA_M = 3.0  # the receiver's altitude noise (m)
GNSS_HZ = 5.0
# A MAD-based sigma of n white-noise samples scatters by about 1.17 sigma / sqrt(n) (its
# efficiency is 37 % of the standard deviation's).
MAD_SPREAD = 1.17

GNSS_MAP = {**COLUMN_MAP, "gnss": {"file": "gps.csv", "latitude": "lat", "longitude": "lon",
                                   "altitude": {"column": "alt", "unit": "m"}}}


def write_gnss(flight: Flight, path: Path, seed: int, tail_jumps: tuple[float, ...] = ()
               ) -> pd.DataFrame:
    """GNSS fixes at GNSS_HZ over the whole flight (time in ms like the log's), the true
    altitude above mean sea level with GNSS_SIGMA_M of noise; `tail_jumps` (m) added to the
    last fixes, a receiver losing its lock on the ground.  Returns the fixes written."""
    rng = np.random.default_rng(seed)
    phase = (flight.t * GNSS_HZ) % 1.0
    fix = np.isclose(phase, 0.0, atol=1e-6) | np.isclose(phase, 1.0, atol=1e-6)
    alt = SITE.elevation_m + flight.h[fix] + rng.normal(0.0, GNSS_SIGMA_M, int(fix.sum()))
    if tail_jumps:
        alt[-len(tail_jumps):] += tail_jumps
    fixes = pd.DataFrame({"t_ms": np.round(1e3 * flight.t[fix]).astype(int),
                          "lat": 32.94 + 1e-5 * flight.t[fix], "lon": -106.9, "alt": alt})
    fixes.to_csv(path, index=False, float_format="%.7g")
    return fixes


def _run_import(folder: Path, card: dict, column_map: dict) -> tuple[int, str]:
    (folder / "map.json").write_text(json.dumps(column_map))
    (folder / "card.json").write_text(json.dumps(card))
    screen = io.StringIO()
    with contextlib.redirect_stdout(screen):
        code = main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                     "--card", str(folder / "card.json"), "--out", str(folder / "test")])
    return code, screen.getvalue()


@dataclass(frozen=True)
class Imported:
    flight: Flight
    folder: Path
    report: dict
    screen: str


@pytest.fixture(scope="module")
def gnss_descent(tmp_path_factory: pytest.TempPathFactory) -> Imported:
    """A drogue deployed a second after apogee and nothing else; the altimeter's file
    (barometer and accelerometer) ends at apogee, the GNSS's at 5 Hz goes on to the ground.
    The card's mass is what flew (the generator flies the main's dry mass too), and its
    model the default one (the air's vertical motion at a knot every 4 s)."""
    folder = tmp_path_factory.mktemp("gnss_descent")
    flight = fly(chutes=("drogue",), thrust_n=700.0)
    write_mapped(flight, folder / "log.csv", seed=21, end_s=flight.events["apogee"])
    write_gnss(flight, folder / "gps.csv", seed=22)
    card = {k: v for k, v in CARD.items() if k != "model"}
    card["vehicle"] = {**CARD["vehicle"], "mass": {"value": MASS + DRY_MASS["main"],
                                                   "unit": "kg"}}
    card["parachutes"] = [CARD["parachutes"][0]]
    code, screen = _run_import(folder, card, GNSS_MAP)
    assert code == 0, screen
    return Imported(flight, folder / "test",
                    json.loads((folder / "test" / "import.json").read_text()), screen)


def test_a_descent_logged_only_by_the_gnss_imports(gnss_descent: Imported) -> None:
    """The GNSS carries the descent: said on screen and in import.json; touchdown is the
    GNSS's; the folder's altitude series is the GNSS's, at a sigma from its scatter; the
    altimeter, which reads none of the phase, is left out with a note."""
    flight, report = gnss_descent.flight, gnss_descent.report
    assert report["descent_channel"] == "gps_altitude"
    [carried] = [n for n in report["notes"] if n.startswith("the GNSS altitude carries")]
    assert "the barometer's samples end at" in carried
    assert "the descent is read in the GNSS altitude" in gnss_descent.screen
    assert f"note: {carried}" in gnss_descent.screen
    assert any(n.startswith("altimeter: its samples end at") and "left out of the folder" in n
               for n in report["notes"])
    landed = report["flight_events"]["landed"]
    assert landed["source"] == "GNSS altitude"
    assert abs(landed["time_s"] - flight.events["landed"]) <= 3.0 * landed["sigma_s"]
    test = load_test(gnss_descent.folder)
    assert [s.kind for s in test.sensors] == ["gps_altitude"]
    [gps] = test.sensors
    assert gps.time[0] <= test.t_start and gps.time[-1] >= test.t_end
    # Written in metres above mean sea level about the site's datum: off the true altitude
    # by the noise alone.
    truth = SITE.elevation_m + np.interp(gps.time, flight.t, flight.h)
    error = np.asarray(gps.data["up"], float) - truth
    n = error.size
    assert abs(float(np.std(error)) - GNSS_SIGMA_M) <= 3.0 * GNSS_SIGMA_M / np.sqrt(2 * n)
    # Its sigma from its scatter over the later half of the descent, within three times a
    # robust sigma's sampling error over those fixes.
    later = int(np.sum((gps.time >= 0.5 * (test.t_start + test.t_end))
                       & (gps.time <= test.t_end)))
    assert report["gnss_sigma_m"] == pytest.approx(GNSS_SIGMA_M,
                                                   abs=3.0 * MAD_SPREAD * GNSS_SIGMA_M
                                                   / np.sqrt(later))
    manifest = json.loads((gnss_descent.folder / "manifest.json").read_text())
    [entry] = manifest["sensors"]
    assert entry["sigma"]["altitude"]["value"] == pytest.approx(report["gnss_sigma_m"],
                                                                abs=1e-3)
    assert "gps_altitude" in manifest["model"]["effects"]


def test_the_gnss_descent_s_drag_area_agrees_with_the_truth(gnss_descent: Imported) -> None:
    """The deployment forensics read the drogue's settled descent in the GNSS altitude: the
    drag area it needs (the drogue's and the airframe's) within three of its stated
    sigmas of the truth, a sigma that says something (under 5 %)."""
    drogue = gnss_descent.report["deployments"]["drogue"]
    assert drogue["verdict"] == "opened"
    truth = CDS["drogue"] + CDS_BODY
    assert drogue["drag_area_sigma_m2"] < 0.05 * truth
    assert abs(drogue["drag_area_m2"] - truth) <= 3.0 * drogue["drag_area_sigma_m2"]


def test_the_gnss_descent_reconstructs(gnss_descent: Imported) -> None:
    """One reconstruction of the folder: the drogue's drag area within two of its sigmas
    of the truth, a result."""
    from cpas_ocp import api

    rec = api.reconstruct(gnss_descent.folder)
    row = rec.parameters.loc["CdS[drogue,stage1]"]
    assert rec.is_result, rec.problems
    assert 0.0 < row["sigma"] < 0.1 * CDS["drogue"]
    assert abs(row["value"] - CDS["drogue"]) <= 2.0 * row["sigma"]


def test_files_of_different_spans_import_each_over_its_own(tmp_path: Path) -> None:
    """The altimeter's file ends 0.05 s after the drogue's charge; the accelerometer's, in
    a file of its own, and the GNSS's go on to the ground, the GNSS's last fixes jumping by
    tens of metres.  The charge's pressure pulse at the altimeter's end is the drogue's
    charge (not a damaged end, not the impact: a note says so), the main's charge is the
    accelerometer's, touchdown the GNSS's; the altimeter, which reads none of the phase,
    is left out with a note, never ending the phase; no GNSS fix is a charge."""
    flight = fly()
    p, a = sensor_readings(flight, seed=31)
    rng = np.random.default_rng(32)
    t_ms = np.round(1e3 * flight.t).astype(int)
    baro = flight.t <= flight.events["drogue"] + 0.05
    pd.DataFrame({"t_ms": t_ms[baro], "press_hPa": np.round(p[baro] / 100.0, 2)}).to_csv(
        tmp_path / "log.csv", index=False, float_format="%.7g")
    n = flight.t.size
    pd.DataFrame({"t_ms": t_ms, "ax_g": np.round(rng.normal(0, 0.03, n), 4),
                  "ay_g": np.round(-(a + 9.80665) / 9.80665, 4),
                  "az_g": np.round(rng.normal(0, 0.03, n), 4)}).to_csv(
        tmp_path / "accel.csv", index=False, float_format="%.7g")
    write_gnss(flight, tmp_path / "gps.csv", seed=33, tail_jumps=(80.0, -60.0, 120.0))
    column_map = {"recorder": "altimeter, IMU and GNSS files",
                  "time": {"column": "t_ms", "unit": "ms"},
                  "pressure": {"column": "press_hPa", "unit": "hPa"},
                  "acceleration": {**COLUMN_MAP["acceleration"], "file": "accel.csv"},
                  "gnss": GNSS_MAP["gnss"]}
    code, screen = _run_import(tmp_path, CARD, column_map)
    assert code == 0, screen
    report = json.loads((tmp_path / "test" / "import.json").read_text())
    events = report["flight_events"]
    assert set(events) == {"boost", "coast", "apogee", "drogue", "main", "landed"}
    drogue = events["drogue"]
    assert drogue["source"] == "accelerometer and altimeter"
    assert abs(drogue["time_s"] - sample_time(flight, flight.events["drogue"])) <= 2 * DT
    main_ = events["main"]
    assert main_["source"] == "accelerometer"
    assert abs(main_["time_s"] - flight.events["main"]) <= 3.0 * main_["sigma_s"]
    assert events["landed"]["source"] == "GNSS altitude"
    assert abs(events["landed"]["time_s"] - flight.events["landed"]) <= \
        3.0 * events["landed"]["sigma_s"]
    notes = report["notes"]
    assert any("an ejection charge's pressure pulse, not an impact" in n for n in notes)
    assert not any("impact on the ground" in n or "ejection-like" in n for n in notes)
    assert any(n.startswith("the GNSS altitude carries the descent") for n in notes)
    assert any(n.startswith("altimeter: its samples end at") and "left out of the folder" in n
               for n in notes)
    assert "damaged_end_samples" not in report["dropped"]
    test = load_test(tmp_path / "test")
    # The phase ends at the GNSS's touchdown, not where the altimeter's file ends.
    assert test.t_end > flight.events["landed"] - 3.0
    assert sorted(s.kind for s in test.sensors) == ["axial_accelerometer", "gps_altitude"]
    # The card's model lists its effects: the GNSS's measurement is added, and said.
    manifest = json.loads((tmp_path / "test" / "manifest.json").read_text())
    assert "gps_altitude" in manifest["model"]["effects"]
    assert any("lists no gps_altitude effect" in n for n in notes)


def test_a_lapse_rate_fitted_to_a_descent_the_barometer_does_not_read_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``"lapse_rate": "gps"`` fits the GNSS against the barometer over the descent: with
    the GNSS alone reading it, one line naming the card's field, exit 2, nothing written."""
    flight = fly(chutes=("drogue",), thrust_n=700.0)
    write_mapped(flight, tmp_path / "log.csv", seed=21, end_s=flight.events["apogee"])
    write_gnss(flight, tmp_path / "gps.csv", seed=22)
    card = {**CARD, "parachutes": [CARD["parachutes"][0]],
            "site": {**CARD["site"], "lapse_rate": "gps"}}
    code, _ = _run_import(tmp_path, card, GNSS_MAP)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: {tmp_path / 'card.json'}: site.lapse_rate:")
    assert "barometer ends at" in err[0]
    assert not (tmp_path / "test").exists()
