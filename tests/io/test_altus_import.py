"""Altus Metrum import, site atmosphere and barometric altimeter model.

The reader is tested on a log written here in AltOS's CSV layout, quirks
included, from a known descent; the real logs are read by
`test_prometheus.py` when the shared data folder is present.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.altus_metrum import read_altus_log
from cpas_ocp.io.flight_card import card_from_dict, load_card
from cpas_ocp.io.flight_events import second_difference_sigma
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.log_noise import settled_time
from cpas_ocp.io.opening_loads import opening_peak
from cpas_ocp.io.site_air import fit_lapse_rate
from cpas_ocp.physics.atmosphere import (
    SiteAtmosphere,
    StandardAtmosphere,
    density_at,
    geometric_altitude,
    pressure_altitude,
)
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.units import G0
from cpas_ocp.reports.import_text import import_text

pytestmark = pytest.mark.slow

SITE = SiteAtmosphere.from_surface_density(1401.0, 86300.0, 1.001, 0.008)
HEADER = ("#version,serial,flight,call,time,state,state_name,acceleration,pressure,altitude,"
          "height,speed,temperature,accel_x,accel_y,accel_z,gyro_roll,gyro_pitch,gyro_yaw,"
          "nsat,latitude,longitude,altitude,hdop")


def _pressure_at(h: np.ndarray) -> np.ndarray:
    return np.array([float(SITE.pressure(float(x))) for x in np.atleast_1d(h)])


def _write_log(path: Path, seed: int, peak: float = 150.0,
               accel_until: float = np.inf) -> dict[str, float]:
    """An AltOS-layout log of a known descent: pad, boost/coast, 30 m/s drogue descent
    from 3000 m above the pad, main at 400 m, 6 m/s to the ground.  The axial
    accelerometer reads 1 g less than the specific force with 2 m/s^2 noise (NaN after
    `accel_until`, s); the main's charge jolts it by -50 m/s^2 and its opening
    pulls a `peak` (m/s^2) one second later (returned as ``main_open``)."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([np.arange(-0.3, 0.0, 0.01), np.arange(0.0, 20.0, 0.01),
                        np.arange(20.0, 190.0, 0.1)])
    h_agl = np.where(t < 0, 0.0, np.where(t < 20.0, 3000.0 * np.sin(np.pi / 40 * t), 0.0))
    drogue, main = 20.0, 20.0 + 2600.0 / 30.0
    h_agl = np.where(t >= drogue, 3000.0 - 30.0 * (t - drogue), h_agl)
    h_agl = np.where(t >= main, 400.0 - 6.0 * (t - main), h_agl)
    h_agl = np.maximum(h_agl, 0.0)
    state = np.where(t < 4, "boost", np.where(t < drogue, "coast",
                     np.where(t < main, "drogue", np.where(h_agl > 0, "main", "landed"))))
    p = _pressure_at(SITE.elevation_m + h_agl) + rng.normal(0, 5.0, t.size)
    k_main = int(np.argmin(np.abs(t - main)))
    p[k_main] += 1500.0  # the main's ejection charge
    accel = -9.81 + np.random.default_rng(seed + 1).normal(0.0, 2.0, t.size)
    accel[k_main] -= 50.0
    k_open = int(np.argmin(np.abs(t - t[k_main] - 1.0)))
    accel[k_open] += peak
    accel[t > accel_until] = np.nan
    fix_every = 1.0
    lines = [HEADER]
    last_fix = -10.0
    gps = (32.9, -106.9, SITE.elevation_m)
    for k in range(t.size):
        if t[k] - last_fix >= fix_every:
            last_fix = t[k]
            gps = (32.9 + 1e-5 * k, -106.9, SITE.elevation_m + h_agl[k] + rng.normal(0, 3.0))
        speed = "NaN" if k < 40 else f"{-30.0:8.2f}"
        for stamp in (t[k], t[k] + 0.04) if k % 7 == 3 and t[k] > drogue else (t[k],):
            # A second stamp (in the 10 Hz descent) is another record's row repeating the
            # sensor sample.
            lines.append(
                f"6, 6583, 3,VE3LIC, {stamp:8.2f}, 3, {state[k]:>7s}, {accel[k]:7.2f}, "
                f"{p[k]:9.2f}, {float(pressure_altitude(p[k])):8.2f}, {h_agl[k]:8.2f}, {speed}, "
                f"30.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 11, {gps[0]:12.7f},{gps[1]:12.7f}, "
                f"{gps[2]:7.1f},2147483647.0")
        if k % 200 == 7:  # AltOS repeats a time stamp now and then
            lines.append(lines[-1])
    path.write_text("\n".join(lines) + "\n")
    return {"drogue": float(t[np.argmax(t >= drogue)]), "main": float(t[np.argmax(t >= main)]),
            "main_open": float(t[k_open])}


CARD = {
    "name": "synthetic_rocket", "kind": "flight_log", "title": "a known descent",
    "data": {"folder": "", "logs": []},
    "vehicle": {"name": "rocket", "mass": {"value": 16.0, "unit": "kg"},
                "forebody_cds": {"value": 0.0, "unit": "m^2"}},
    "parachutes": [
        {"name": "drogue", "type": "drogue", "deployment": "drogue",
         "diameter": {"value": 24, "unit": "in"}, "dry_mass": {"value": 0.1, "unit": "kg"},
         "inflation": "finite_mass", "stages": ["stage1"]},
        {"name": "main", "type": "main", "deployment": "main",
         "diameter": {"value": 72, "unit": "in"}, "dry_mass": {"value": 0.5, "unit": "kg"},
         "inflation": "finite_mass", "stages": ["stage2"]}],
    "site": {"elevation": {"value": 1401, "unit": "m"},
             "surface_density": {"value": 1.001, "unit": "kg/m^3"}, "lapse_rate": "gps"},
    "model": {"effects": ["canopy_inflation", "forebody_drag", "rigid_riser", "baro"]},
}


def test_pressure_altitude_inverts_the_standard_atmosphere() -> None:
    h = np.array([0.0, 1330.0, 5000.0, 10000.0])
    p = np.array([float(StandardAtmosphere().pressure(x)) for x in h])
    assert np.allclose(pressure_altitude(p), h, atol=1e-6)
    # AltOS's reading on the Prometheus pad: 86,338 Pa is 1329.7 m.
    assert float(pressure_altitude(86338.1)) == pytest.approx(1329.70, abs=0.01)


def test_site_atmosphere_is_hydrostatic_and_invertible() -> None:
    """dp/dh = -rho g0 (checked by finite differences) and altitude_at_pressure inverts it."""
    for h in (1401.0, 3000.0, 5500.0):
        dp = (float(SITE.pressure(h + 0.5)) - float(SITE.pressure(h - 0.5)))
        assert dp == pytest.approx(-float(density_at(SITE, h)[0]) * 9.80665, rel=1e-6)
    assert float(density_at(SITE, 1401.0)[0]) == pytest.approx(1.001, rel=1e-12)
    h = np.array([1401.0, 2500.0, 5538.0])
    assert np.allclose(SITE.altitude_at_pressure(_pressure_at(h)), h, atol=1e-6)
    assert np.allclose(geometric_altitude(SITE, pressure_altitude(_pressure_at(h))), h,
                       atol=1e-6)
    # A hot day: the altimeter under-reads the height gained, here by about 5 %.
    gain = float(pressure_altitude(float(SITE.pressure(4401.0)))
                 - pressure_altitude(float(SITE.pressure(1401.0))))
    assert 0.9 < gain / 3000.0 < 0.97


def test_reader_survives_the_altos_quirks(tmp_path: Path) -> None:
    events = _write_log(tmp_path / "log.csv", seed=1)
    log = read_altus_log(tmp_path / "log.csv")
    d = log.data
    assert log.recorder == "Altus Metrum"  # a renamed export: no product in its name
    assert log.duplicate_times > 0 and d["time"].is_monotonic_increasing
    assert not d["time"].duplicated().any()
    assert "gps_altitude" in d.columns and d["gps_altitude"].iloc[0] > 1000.0
    assert d["altitude"].iloc[0] == pytest.approx(float(pressure_altitude(86300.0)), abs=3.0)
    assert d["hdop"].isna().all()  # the 2^31 - 1 sentinel
    assert log.events["drogue"] == pytest.approx(events["drogue"])
    assert log.events["main"] == pytest.approx(events["main"])
    fixes = log.gps_fixes()
    assert len(fixes) == pytest.approx(d["time"].iloc[-1] - d["time"].iloc[0], abs=3)
    # Every seventh descent sample is repeated 40 ms later by another record's row: those
    # rows go.
    fresh = log.sensor_samples()
    n_descent = int(np.sum(d["time"].to_numpy() > events["drogue"] + 0.05))
    assert len(d) - len(fresh) == pytest.approx(n_descent / 8, abs=2)
    copies = (fresh[["pressure", "acceleration"]].diff() == 0.0).all(axis=1)
    assert not copies.iloc[1:].any()


def test_import_writes_a_loadable_test_folder(tmp_path: Path) -> None:
    events = _write_log(tmp_path / "log.csv", seed=2)
    log = read_altus_log(tmp_path / "log.csv")
    summary = import_flight(log, card_from_dict(CARD, "card.json"), tmp_path / "test")
    test = load_test(tmp_path / "test")
    assert {s.kind for s in test.sensors} == {"baro", "gps_altitude", "axial_accelerometer"}
    assert test.t_start == pytest.approx(events["drogue"])
    # Touchdown: 400 m at 6 m/s after the main.
    assert summary.events["touchdown"] == pytest.approx(events["main"] + 400.0 / 6.0, abs=0.6)
    # The ejection-charge sample is gone from the altimeter series.
    baro = test.sensors_of("baro")[0]
    assert np.abs(baro.time - events["main"]).min() > 0.05
    assert summary.dropped["ejection_charge_samples"] >= 1
    assert summary.dropped["repeated_sensor_rows"] > 0
    late = np.isclose(np.round(baro.time * 100.0) % 10, 4)  # the copies' stamps, 40 ms late
    assert not np.any(late & (baro.time > events["drogue"]))
    # The lapse rate fitted to the GPS fixes recovers the truth: 3 m GPS noise over
    # 3 km of height gives a sigma of a few hundredths of a K/km.
    lapse, _, resid = summary.lapse_fit
    assert lapse == pytest.approx(SITE.lapse_rate_k_m, abs=3e-4)
    assert resid == pytest.approx(3.0, rel=0.3)
    # The altimeter sigma under the main is the pressure noise, 5 Pa / (rho g) = 0.5 m.
    assert summary.baro_sigma_m[1] == pytest.approx(5.0 / (1.0 * 9.80665), rel=0.35)
    # The accelerometer's: its 2 m/s^2 noise under each canopy's steady descent (no swing
    # simulated), and apart the main's opening, whose 150 m/s^2 peak the drag can pull
    # (30 m/s at the charge, 6 m/s settled: up to 25 g), so it stays, in the opening's
    # sigma.  The charge jolt is gone with the altimeter's charge samples.
    assert len(summary.accel_sigma) == 3
    assert summary.accel_sigma[0] == pytest.approx(2.0, rel=0.2)
    assert summary.accel_sigma[2] == pytest.approx(2.0, rel=0.2)
    assert summary.accel_sigma[1] > 5.0 * summary.accel_sigma[0]
    snatch = summary.snatches["main"]
    # (30 / 6)^2 g less one g; the densities at the charge and in the settled descent, tens
    # of metres apart, differ by well under 1 %.
    assert snatch.ceiling_m_s2 == pytest.approx(25.0 * G0 - G0, rel=0.02)
    assert snatch.samples_left_out == 0 and snatch.largest_m_s2 is None
    accel = test.sensors_of("axial_accelerometer")[0]
    assert np.abs(accel.time - events["main"]).min() > 0.05
    assert summary.dropped["ejection_charge_accelerometer_samples"] >= 1
    manifest = json.loads((tmp_path / "test" / "manifest.json").read_text())
    assert manifest["atmosphere"]["model"] == "site"
    # The main does not start to inflate before its ejection charge (less the event's sigma),
    # however wide the start window.
    charge = test.event("mortar_fire", "main")
    starts = {p.name: p for p in CanopyInflation(start_window=5.0).parameters(test)}
    assert starts["t_start[main,stage2]"].lower == pytest.approx(charge.time - charge.sigma)
    assert starts["t_start[main,stage2]"].upper == pytest.approx(charge.time + 0.5 + 5.0)
    # The main's opening peak, not the charge's jolt, is reported as its full-open time;
    # the drogue, opened near apogee, has none.  The folder has the accelerometer's
    # samples of that opening, so the peak is not also fitted as the fill's end.
    assert summary.events["main full open"] == pytest.approx(events["main_open"])
    assert test.event("full_open", "main") is None
    assert test.event("full_open", "drogue") is None
    # Where the accelerometer's series is not written (it stops reading inside the phase)
    # the peak is the main's full-open event, one 10 Hz sample its sigma ...
    _write_log(tmp_path / "short.csv", seed=2, accel_until=events["main"] + 20.0)
    import_flight(read_altus_log(tmp_path / "short.csv"), card_from_dict(CARD, "card.json"),
                  tmp_path / "no_accel")
    test = load_test(tmp_path / "no_accel")
    assert not test.sensors_of("axial_accelerometer")
    full = test.event("full_open", "main")
    assert full is not None and full.stage == "stage2"
    assert full.time == pytest.approx(events["main_open"]) and full.sigma == pytest.approx(0.1)
    # ... which the model predicts at the end of the main's fill, t_i + n D / V_i.
    model = Estimator(test).model
    values = {p.name: p.default for p in model.parameters}
    v_start = 27.0
    captured = {c.name: v_start for c in model.captures}
    [predicted] = np.asarray(model.event_times(model.parameter_vector(values),
                                               model.capture_vector(captured))).ravel()
    fill = values["n[main,stage2]"] * test.parachute("main").diameter / v_start
    assert predicted == pytest.approx(values["t_start[main,stage2]"] + fill, rel=1e-12)


def test_a_reading_above_the_drag_ceiling_is_left_out_as_the_snatch(tmp_path: Path) -> None:
    """A 300 m/s^2 opening peak is more than the main's drag can pull at the charge's
    30 m/s (about 235 m/s^2 as read, the settled 6 m/s giving the full drag area): the
    import leaves it out of the fitted series and says so, and its time is still the
    opening's reported full-open time."""
    events = _write_log(tmp_path / "log.csv", seed=2, peak=300.0)
    summary = import_flight(read_altus_log(tmp_path / "log.csv"),
                            card_from_dict(CARD, "card.json"), tmp_path / "test")
    snatch = summary.snatches["main"]
    assert snatch.samples_left_out == 1 and snatch.at_s == pytest.approx(events["main_open"])
    assert snatch.largest_m_s2 > snatch.ceiling_m_s2
    assert summary.dropped["snatch_samples_above_drag_ceiling"] == 1
    test = load_test(tmp_path / "test")
    accel = test.sensors_of("axial_accelerometer")[0]
    assert np.abs(accel.time - events["main_open"]).min() > 0.05
    assert summary.events["main full open"] == pytest.approx(events["main_open"])
    report = json.loads((tmp_path / "test" / "import.json").read_text())
    assert report["snatch"]["main"]["samples_left_out"] == 1
    assert "left out as the shock cord's snatch" in import_text(summary)


def test_opening_peak_stands_off_the_steady_reading() -> None:
    """Under a swinging drogue the axial reading scatters by 5 m/s^2 (seeded) about
    -16 m/s^2; the charge at 10 s jolts it.  A 200 m/s^2 pulse a second later is the
    opening; one of 15 m/s^2 (three scatter sigmas) is not told from the swinging."""
    rng = np.random.default_rng(5)
    t = np.round(np.arange(0.0, 20.0, 0.1), 2)
    a = -16.0 + rng.normal(0.0, 5.0, t.size)
    a[t == 10.0] -= 50.0
    for pulse, expected in ((200.0, (11.0, 0.1)), (15.0, None)):
        reading = a + pulse * (t == 11.0)
        found = opening_peak(pd.DataFrame({"time": t, "acceleration": reading}), 10.0)
        assert found == (None if expected is None else pytest.approx(expected))
    # Too few samples before the charge to know the steady reading.
    assert opening_peak(pd.DataFrame({"time": t[95:], "acceleration": a[95:]}), 10.0) is None


def test_lapse_rate_fit_is_unbiased_without_noise() -> None:
    h = np.linspace(1500.0, 5000.0, 50)
    t = np.arange(h.size, dtype=float)
    fixes = {"time": t, "gps_altitude": h - 11.0}
    lapse, offset, resid = fit_lapse_rate(pd.DataFrame(fixes), pd.Series(_pressure_at(h)),
                                          pd.Series(t), SITE.elevation_m, SITE.pressure_pa,
                                          SITE.temperature_k)
    assert lapse == pytest.approx(SITE.lapse_rate_k_m, rel=1e-4)
    assert offset == pytest.approx(-11.0, abs=0.05)
    assert resid < 0.05


def test_settled_time_waits_for_the_opening_to_end() -> None:
    """A 30 m/s descent slowing to 6 m/s with a 1 s time constant from t0 = 10 s: the rate
    is within 1.25 x 6 m/s from t0 + ln(24 / 1.5) = t0 + 2.8 s on; a 2 s window reaches it
    up to one window earlier.  0.5 m altimeter noise at 10 Hz (seeded)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 60.0, 0.1)
    x = np.clip(t - 10.0, 0.0, None)
    h = 3000.0 - 30.0 * np.minimum(t, 10.0) - 6.0 * x - 24.0 * (1.0 - np.exp(-x))
    h = h + rng.normal(0.0, 0.5, t.size)
    settled = settled_time(t, h, 10.0, 60.0)
    assert 10.0 + 1.5 <= settled <= 10.0 + 3.0
    # An instant change of rate has settled at once.
    step = 3000.0 - 30.0 * np.minimum(t, 10.0) - 6.0 * x + rng.normal(0.0, 0.5, t.size)
    assert settled_time(t, step, 10.0, 60.0) == pytest.approx(10.0, abs=0.6)


def test_second_difference_sigma_recovers_white_noise() -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(0, 100, 4000)
    x = 1000.0 - 25.0 * t + 0.01 * t**2 + rng.normal(0, 2.0, t.size)
    # 1.4826 MAD has a relative standard error of about 1.1/sqrt(n) = 2 %.
    assert second_difference_sigma(x) == pytest.approx(2.0, rel=0.08)


@pytest.mark.parametrize("text, field", [
    ("not a log\n1,2,3\n", "line 1"),
    ("#version,serial,time\n1,2,3\n", "state_name"),
])
def test_bad_logs_are_input_errors(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        read_altus_log(path)
    assert err.value.field == field and str(path) in str(err.value)


def test_card_errors_name_the_field(tmp_path: Path) -> None:
    bad = {**CARD, "parachutes": [{k: v for k, v in CARD["parachutes"][0].items()
                                   if k != "deployment"}]}
    with pytest.raises(InputError, match=r"parachutes\[0\]\.deployment"):
        card_from_dict(bad, "card.json")
    with pytest.raises(InputError, match="prometheus"):
        load_card("no_such_flight")
    _write_log(tmp_path / "log.csv", seed=4)
    log = read_altus_log(tmp_path / "log.csv")
    late = {**CARD, "parachutes": [{**CARD["parachutes"][0], "deployment": "cutter"}]}
    with pytest.raises(InputError,
                       match=r"parachutes\[0\]\.deployment: a flight state .*drogue "
                             r"\d+\.\d\d ± 0\.10 s \(flight state\).*got 'cutter'"):
        import_flight(log, card_from_dict(late, "card.json"), tmp_path / "t")
    assert not (tmp_path / "t").exists()


def test_builtin_card_names_its_data() -> None:
    card = load_card("prometheus")
    assert card.data_folder == "prometheus-2022" and len(card.logs) == 2
    assert math.isclose(card.nominal["CdS[drogue,stage1]"]["value"], 0.467)


def test_import_command_writes_the_folder_and_flight_refuses_missing_logs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _write_log(tmp_path / "log.csv", seed=5)
    (tmp_path / "card.json").write_text(json.dumps(CARD))
    assert main(["import-altus", str(tmp_path / "log.csv"), "--card",
                 str(tmp_path / "card.json"), "--out", str(tmp_path / "test")]) == 0
    assert load_test(tmp_path / "test").name == "synthetic_rocket"
    code = main(["flight", "prometheus", "--out", str(tmp_path / "out"),
                 "--data", str(tmp_path / "nowhere")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "nowhere" in err[0] and "--data" in err[0]
    assert not (tmp_path / "out").exists()


def test_the_interface_reads_a_log_the_way_its_card_says(tmp_path: Path) -> None:
    """`co.import_log` without a format takes the card's ``data.format``; a card that says
    neither a format nor a column map is refused, naming both fields."""
    import cpas_ocp as co
    _write_log(tmp_path / "log.csv", seed=2)
    card = tmp_path / "card.json"
    card.write_text(json.dumps({**CARD, "data": {"folder": "", "logs": [], "format": "altus"}}))
    summary = co.import_log(tmp_path / "log.csv", str(card), tmp_path / "test")
    assert load_test(tmp_path / "test").t_start == pytest.approx(summary.events["drogue"])
    silent = tmp_path / "silent.json"
    silent.write_text(json.dumps(CARD))
    with pytest.raises(InputError, match=r"data\.format/data\.columns"):
        co.import_log(tmp_path / "log.csv", str(silent), tmp_path / "other")
    assert not (tmp_path / "other").exists()
