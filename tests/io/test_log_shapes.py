"""Real exports come in shapes a tidy log does not: one canopy, a log that ends at its
deployment, a dead accelerometer, a log that starts at launch, several files and time
bases, a charge no detector sees, a card that gives only what its author knows.

Each test flies the known rocket of `test_rocket_log_import` (seeded noise), writes
the log in the shape at hand, and imports it with one command.  Expectations come
from the generator's truth: event times within the stated sigmas, the pad's level
within the barometer's noise, the descent's drag area within what the forebody's and
the air's share allow.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import (
    CDS,
    CDS_BODY,
    GROUND_M,
    H_TABLE,
    MAIN_AGL_M,
    P_TABLE,
    SITE,
    Flight,
    fly,
    sample_time,
    sensor_readings,
)
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.physics.atmosphere import pressure_altitude
from cpas_ocp.physics.units import G0
from tests.io.test_rocket_log_import import CARD, DT, write_mapped

FT = 0.3048


@pytest.fixture(scope="module")
def flight() -> Flight:
    return fly()


def _write(tmp_path: Path, name: str, obj: dict) -> str:
    path = tmp_path / name
    path.write_text(json.dumps(obj))
    return str(path)


def _import(tmp_path: Path, log: Path, column_map: dict, card: dict,
            capsys: pytest.CaptureFixture[str] | None = None) -> tuple[int, dict | None, str]:
    """Run `cpas-ocp import`; (exit code, import.json or None, stderr)."""
    code = main(["import", str(log), "--columns", _write(tmp_path, "map.json", column_map),
                 "--card", _write(tmp_path, "card.json", card), "--out",
                 str(tmp_path / "test")])
    err = capsys.readouterr().err if capsys is not None else ""
    report = json.loads((tmp_path / "test" / "import.json").read_text()) if code == 0 else None
    return code, report, err


AXIAL_MAP = {"recorder": "one-axis logger", "time": {"column": "t", "unit": "s"},
             "pressure": {"column": "p", "unit": "Pa"},
             "acceleration": {"column": "acc", "unit": "m/s^2", "gravity": "subtracted"}}


def _table(flight: Flight, seed: int) -> pd.DataFrame:
    p, a = sensor_readings(flight, seed)
    return pd.DataFrame({"t": flight.t, "p": np.round(p, 1), "acc": np.round(a, 3)})


def test_single_canopy_main_at_apogee(tmp_path: Path) -> None:
    """One main fired at apogee (the charge near apogee is the log's ``drogue`` event): the
    card with one canopy imports, with its charge as the canopy's mortar fire within two
    samples of the truth, and the folder builds its model (the card's diameter bounds the
    drag area above the truth)."""
    single = fly(chutes=("main",))
    _table(single, 5).to_csv(tmp_path / "log.csv", index=False)
    card = {**CARD, "parachutes": [{**CARD["parachutes"][1], "deployment": "drogue"}]}
    code, _, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card)
    assert code == 0
    test = load_test(tmp_path / "test")
    [charge] = [e for e in test.events if e.name == "mortar_fire"]
    assert charge.parachute == "main"
    assert abs(charge.time - sample_time(single, single.events["main"])) <= 2 * DT + 1e-9
    assert test.t_start == pytest.approx(charge.time)
    model = spec_of_test(test).model(test)
    assert "CdS[main,stage2]" in model.parameter_names


def test_log_ending_at_its_deployment_is_one_line(flight: Flight, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A log that ends a second after the drogue's charge holds no descent to fit: one line
    naming the log, what was expected and how long it went on, exit 2, no folder."""
    table = _table(flight, 6)
    table[flight.t <= flight.events["drogue"] + 1.0].to_csv(tmp_path / "log.csv", index=False)
    card = {**CARD, "parachutes": CARD["parachutes"][:1]}
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert "log.csv" in lines[0] and "descent of at least" in lines[0]
    assert "the log ends" in lines[0]
    assert not (tmp_path / "test").exists()


def test_dead_accelerometer_is_left_out_with_a_note(flight: Flight, tmp_path: Path) -> None:
    """An accelerometer that reads exactly 0.0 from apogee on (a recorder that stops
    logging it) is not data: its dead samples are left out with a note naming the channel
    and the span, so the folder fits the altimeter alone; the boost it did measure still
    gives the boost event."""
    table = _table(flight, 7)
    table.loc[flight.t >= flight.events["apogee"], "acc"] = 0.0
    table.to_csv(tmp_path / "log.csv", index=False)
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, CARD)
    assert code == 0 and report is not None
    [note] = [n for n in report["notes"] if n.startswith("accelerometer:")]
    assert "did not measure" in note and "(0 m/s^2)" in note
    assert not (tmp_path / "test" / "accelerometer.csv").exists()
    assert abs(report["flight_events"]["boost"]["time_s"] - flight.events["boost"]) <= 2 * DT


def test_a_clipped_accelerometer_loses_its_rail_samples(flight: Flight, tmp_path: Path) -> None:
    """An accelerometer whose range ends at 8 g reads exactly 8 g through a snatch that
    lasts five samples at 14 g: those samples are the range, not the force, and are left
    out with a note; the rest of the channel stays."""
    table = _table(flight, 8)
    k = int(np.searchsorted(flight.t, flight.events["main"] + 1.5))
    table.loc[k:k + 4, "acc"] += 14.0 * G0
    table["acc"] = np.minimum(table["acc"], 8.0 * G0)
    table.to_csv(tmp_path / "log.csv", index=False)
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, CARD)
    assert code == 0 and report is not None
    assert any(n.startswith("accelerometer:") for n in report["notes"])
    accel = pd.read_csv(tmp_path / "test" / "accelerometer.csv")
    assert accel["acceleration"].max() < 8.0 * G0
    phase = report["phase_s"]
    assert accel["time"].min() <= phase[0] + 0.1 and accel["time"].max() >= phase[1]


def test_log_starting_at_launch_takes_the_pad_from_its_first_reading(
        flight: Flight, tmp_path: Path) -> None:
    """An altitude-only log (feet above the pad) that starts as the rocket leaves the pad has
    no samples before launch: the pad is its lowest reading before the climb, so the
    landing, 7 m above the pad, reads 7 m in pressure altitude within the barometer's noise
    (taking the pad from the first 50 samples, already in the boost, put it 29 m off)."""
    p, _ = sensor_readings(flight, 9)
    h_agl = (pressure_altitude(p) - pressure_altitude(SITE.pressure_pa)) / FT
    table = pd.DataFrame({"time": flight.t, "alt_ft": np.round(h_agl, 1)})
    table[flight.t >= 0.0].to_csv(tmp_path / "log.csv", index=False)
    column_map = {"time": {"column": "time", "unit": "s"},
                  "altitude": {"column": "alt_ft", "unit": "ft",
                               "offset": float(pressure_altitude(SITE.pressure_pa)) / FT}}
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", column_map, CARD)
    assert code == 0 and report is not None
    assert any("the log starts at launch" in n for n in report["notes"])
    [landing] = [n for n in report["notes"] if n.startswith("touchdown at")]
    expected = float(pressure_altitude(np.interp(GROUND_M, H_TABLE, P_TABLE))
                     - pressure_altitude(SITE.pressure_pa))
    # The pad's reading carries the barometer's noise (2 Pa, 0.2 m) and the log's 0.1 ft
    # rounding; the touchdown's, its median of three seconds.
    assert float(landing.split(", ")[1].split(" m")[0]) == pytest.approx(expected, abs=0.8)


def test_two_files_and_two_time_bases(flight: Flight, tmp_path: Path) -> None:
    """An accelerometer at 100 Hz and an altimeter at 20 Hz, each with its own time column
    in one CSV (the shorter column blank below its end), and GNSS fixes in a second file
    whose clock runs 2 s behind: all three read, the boost from the accelerometer within
    two of its samples, the main's charge from the 20 Hz altimeter within two of its, and
    every GNSS fix with enough satellites kept."""
    p, a = sensor_readings(flight, 10)
    baro = slice(None, None, 5)
    n_baro = flight.t[baro].size
    table = pd.DataFrame({"t_acc": flight.t, "acc_g": np.round((a + G0) / G0, 4)})
    table["t_alt"] = pd.Series(flight.t[baro])
    table["p_hpa"] = pd.Series(np.round(p[baro] / 100.0, 3))
    assert table["t_alt"].notna().sum() == n_baro
    table.to_csv(tmp_path / "log.csv", index=False)
    fix_t = np.arange(0.0, float(flight.t[-1]), 1.0)
    sats = np.where(np.arange(fix_t.size) % 10 == 3, 3, 8)  # every tenth fix too weak
    pd.DataFrame({"gps_time": fix_t - 2.0, "lat": 32.94 + 1e-5 * fix_t,
                  "lon": -106.9 + 1e-5 * fix_t, "sats": sats}).to_csv(
        tmp_path / "gnss.csv", index=False)
    column_map = {"time": {"column": "t_alt", "unit": "s"},
                  "pressure": {"column": "p_hpa", "unit": "hPa"},
                  "acceleration": {"column": "acc_g", "unit": "g",
                                   "time": {"column": "t_acc", "unit": "s"}},
                  "gnss": {"file": "gnss.csv", "time": {"column": "gps_time", "offset": 2.0},
                           "latitude": "lat", "longitude": "lon", "satellites": "sats"}}
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", column_map, CARD)
    assert code == 0 and report is not None
    events = report["flight_events"]
    assert abs(events["boost"]["time_s"] - flight.events["boost"]) <= 2 * DT + 1e-9
    assert abs(events["main"]["time_s"] - flight.events["main"]) <= 2 * 5 * DT + 1e-9
    assert report["dropped"]["gnss_fixes_with_too_few_satellites"] == int((sats < 4).sum())
    [gnss] = [n for n in report["notes"] if n.startswith("GNSS:")]
    assert f"{int((sats >= 4).sum())} fixes" in gnss
    # The altimeter's rows on its own 20 Hz clock: each a sample's time or the mean time of
    # 2^k consecutive ones, so on a half-step grid of that clock (the accelerometer's
    # 100 Hz clock would put most of them off it).
    baro_rows = pd.read_csv(tmp_path / "test" / "baro.csv")
    steps = baro_rows["time"].to_numpy() / (2.5 * DT)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)


def _without_main_charge(flight: Flight, seed: int) -> pd.DataFrame:
    """The log with the main's charge invisible: no pressure pulse, jolt or snatch (a
    recorder whose filter smooths them away)."""
    table = _table(flight, seed)
    k = int(np.searchsorted(flight.t, flight.events["main"] - 1e-9))
    table.loc[k:k + 2, "p"] -= np.array([900.0, 400.0, 150.0])
    table.loc[k:k + 1, "acc"] -= np.array([8.0 * G0, -5.0 * G0])
    snatch = int(np.searchsorted(flight.t, flight.events["main"] + 1.0 - 1e-9))
    table.loc[snatch, "acc"] -= 14.0 * G0
    return table


def test_an_event_the_card_gives_at_a_trigger_altitude(flight: Flight, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """A main charge no detector sees: without the card's word the import stops with one
    line that lists the events it found with their times and sigmas; with "main at the
    300 m crossing ± 0.5 s" the main's mortar fire is the time the altimeter read 300 m
    above the pad on the way down, within two of its samples (an altimeter fires on its
    own reading, the standard atmosphere's height of the pressure: on this hot day 300 m
    of it is 19 m of real height, 0.8 s at the drogue's rate), and carries the card's
    sigma."""
    _without_main_charge(flight, 11).to_csv(tmp_path / "log.csv", index=False)
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, CARD, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert "parachutes[1].deployment" in lines[0] and "'events'" in lines[0]
    assert "drogue " in lines[0] and " ± " in lines[0] and "apogee" in lines[0]
    card = {**CARD, "events": {"main": {"altitude": {"value": MAIN_AGL_M, "unit": "m"},
                                        "sigma": {"value": 0.5, "unit": "s"}}}}
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card)
    assert code == 0 and report is not None
    main_event = report["flight_events"]["main"]
    assert main_event["sigma_s"] == 0.5 and "300 m crossing" in main_event["source"]
    reading = pressure_altitude(np.interp(flight.h, H_TABLE, P_TABLE)) \
        - pressure_altitude(SITE.pressure_pa)
    crossing = flight.t[(flight.t > flight.events["apogee"]) & (reading <= MAIN_AGL_M)][0]
    assert abs(main_event["time_s"] - crossing) <= 2 * DT
    charge = load_test(tmp_path / "test").event("mortar_fire", "main")
    assert charge.time == pytest.approx(main_event["time_s"], abs=1e-3)
    assert charge.sigma == pytest.approx(0.5)


def test_an_event_the_card_gives_at_a_time(flight: Flight, tmp_path: Path) -> None:
    """An event at a time with its sigma (from a video or a pyro log) is taken as given."""
    _without_main_charge(flight, 12).to_csv(tmp_path / "log.csv", index=False)
    t_main = round(flight.events["main"], 2)
    card = {**CARD, "events": {"main": {"time": {"value": t_main, "unit": "s"},
                                        "sigma": {"value": 50, "unit": "ms"}}}}
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card)
    assert code == 0 and report is not None
    assert report["flight_events"]["main"]["time_s"] == t_main
    assert report["flight_events"]["main"]["sigma_s"] == pytest.approx(0.05)


def test_a_card_with_only_what_its_author_knows(flight: Flight, tmp_path: Path) -> None:
    """A card without data, model, diameters, dry masses, canopy types, stages or air
    density imports: the canopies get the documented defaults; each diameter comes from
    the steady descent under it, within 5 % of the diameter whose area at Cd 0.75 is the
    canopy's drag area with the forebody's share (the descent rate measures the whole
    vehicle's); the model is the rocket default for the sensors present, the air's motion
    included, with the drogue's opening shape (at apogee) held; the notes say each
    default."""
    write_mapped(flight, tmp_path / "log.csv", seed=13)
    card = {"name": "bare", "vehicle": {"name": "rocket", "mass": {"value": 16.31,
                                                                  "unit": "kg"}},
            "parachutes": [{"name": "drogue", "deployment": "drogue"},
                           {"name": "main", "deployment": "main"}],
            "site": {"elevation": {"value": 1401, "unit": "m"}}}
    from tests.io.test_rocket_log_import import COLUMN_MAP
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", COLUMN_MAP, card)
    assert code == 0 and report is not None
    manifest = json.loads((tmp_path / "test" / "manifest.json").read_text())
    chutes = {c["name"]: c for c in manifest["parachutes"]}
    assert chutes["drogue"]["type"] == "drogue" and chutes["main"]["type"] == "main"
    assert chutes["main"]["stages"] == ["open"]
    for name in ("drogue", "main"):
        expected = np.sqrt(4.0 * (CDS[name] + (CDS_BODY if name == "drogue" else 0.0))
                           / (np.pi * 0.75))
        assert chutes[name]["diameter"]["value"] == pytest.approx(expected, rel=0.05), name
        assert any(n.startswith(f"{name}: no diameter in the card") for n in report["notes"])
    assert any("standard atmosphere" in n for n in report["notes"])
    effects = [e if isinstance(e, str) else e["effect"] for e in manifest["model"]["effects"]]
    assert {"wind_process", "baro", "axial_accelerometer", "canopy_inflation"} <= set(effects)
    # The drogue's opening (at apogee) read by the accelerometer: its fill constant fitted,
    # its growth held linear.
    assert set(manifest["model"]["fix"]) == {"expopen[drogue,open]"}
    test = load_test(tmp_path / "test")
    assert "wind_up[0]" in spec_of_test(test).model(test).parameter_names


def test_an_empty_model_block_is_the_baseline_for_the_sensors_present(
        flight: Flight, tmp_path: Path) -> None:
    """A manifest whose model block lists no effects (empty, or only fixes) gets the baseline
    with the measurement effect of each sensor kind it has, under its fixes."""
    write_mapped(flight, tmp_path / "log.csv", seed=14)
    from tests.io.test_rocket_log_import import COLUMN_MAP
    card = {**CARD, "model": {"fix": {"expopen[main,stage2]": 1.0}}}
    code, _, _ = _import(tmp_path, tmp_path / "log.csv", COLUMN_MAP, card)
    assert code == 0
    manifest_path = tmp_path / "test" / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["model"] = {"fix": {"expopen[main,stage2]": 1.0}}
    manifest_path.write_text(json.dumps(manifest))
    test = load_test(tmp_path / "test")
    spec = spec_of_test(test)
    assert {"baro", "axial_accelerometer", "canopy_inflation"} <= set(spec.effect_names)
    assert spec.fix == {"expopen[main,stage2]": 1.0}


def test_a_diameter_too_small_for_the_descent_is_named(flight: Flight, tmp_path: Path) -> None:
    """A main's diameter written as 12 in instead of 72 bounds its drag area at 0.22 m^2,
    far below the 5.8 m^2 its descent shows: the import says so before any fit presses
    the bound; the right diameter draws no such note."""
    write_mapped(flight, tmp_path / "log.csv", seed=15)
    from tests.io.test_rocket_log_import import COLUMN_MAP
    small = {**CARD["parachutes"][1], "diameter": {"value": 12, "unit": "in"}}
    card = {**CARD, "parachutes": [CARD["parachutes"][0], small]}
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", COLUMN_MAP, card)
    assert code == 0 and report is not None
    [note] = [n for n in report["notes"] if "check the diameter" in n]
    assert note.startswith("main: the card's diameter 0.30 m")
    right = tmp_path / "right"
    right.mkdir()
    write_mapped(flight, right / "log.csv", seed=15)
    code, report, _ = _import(right, right / "log.csv", COLUMN_MAP, CARD)
    assert code == 0 and report is not None
    assert not any("check the diameter" in n for n in report["notes"])


@pytest.mark.parametrize(("change", "field"), [
    ({"site": {**CARD["site"], "lapse_rate": {"value": 0.0, "unit": "K/km"}}},
     "site.lapse_rate"),
    ({"site": {**CARD["site"], "lapse_rate": {"value": -2.0, "unit": "K/km"}}},
     "site.lapse_rate"),
    ({"events": {"main": {"altitude": {"value": 5000, "unit": "m"},
                          "sigma": {"value": 1, "unit": "s"}}}}, "events.main.altitude"),
    ({"parachutes": [CARD["parachutes"][0], {**CARD["parachutes"][1], "open_at_start": True}]},
     "parachutes[1].open_at_start"),
    ({"parachutes": [CARD["parachutes"][0], {**CARD["parachutes"][1],
                                             "stages": ["reefed", "full"]}]},
     "parachutes[1].stages"),
])
def test_card_mistakes_are_one_line_naming_the_card_field(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str], change: dict,
        field: str) -> None:
    """A card the import cannot honour (a lapse rate of zero or an inversion the site
    atmosphere cannot hold, a trigger height above apogee, a canopy open before the log
    sees it deploy, reefing stages no rocket log times) is refused in one line naming the
    card's field, exit 2, nothing written."""
    _table(flight, 16).to_csv(tmp_path / "log.csv", index=False)
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, {**CARD, **change},
                           capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert lines[0].startswith(f"error: {tmp_path / 'card.json'}: {field}:")
    assert not (tmp_path / "test").exists()


def test_a_log_with_states_holds_the_drogue_opening_at_apogee(tmp_path: Path) -> None:
    """A CATS export logs its flight states but no apogee: the altimeter's apogee is added,
    so the default model holds the opening of the drogue fired at it, as for a log without
    states."""
    from tests.io.test_rocket_log_import import write_cats
    write_cats(fly(), tmp_path / "export", seed=17)
    card = {k: v for k, v in CARD.items() if k != "model"}
    code = main(["import", str(tmp_path / "export"), "--format", "cats", "--card",
                 _write(tmp_path, "card.json", card), "--out", str(tmp_path / "test")])
    assert code == 0
    report = json.loads((tmp_path / "test" / "import.json").read_text())
    assert report["flight_events"]["apogee"]["source"] == "altimeter"
    manifest = json.loads((tmp_path / "test" / "manifest.json").read_text())
    held = manifest["model"]["fix"]
    assert held["expopen[drogue,stage1]"] == 1.0
    # Its fill constant held unless the accelerometer reads the opening.
    accelerometer = any(s["kind"] == "axial_accelerometer" for s in manifest["sensors"])
    assert ("n[drogue,stage1]" in held) is not accelerometer


def test_correlation_length_of_white_and_correlated_noise() -> None:
    """The integrated autocorrelation time is 1 for white noise (ten seeds) and close to
    (1 + a) / (1 - a) = 9 samples for an AR(1) noise with a = 0.8; weighed at
    `block_sigma`, the block means give the standard error of the mean within 15 % of the
    truth, sigma_x sqrt(9 / n) (the sum stops where rho falls into the white band, which
    drops a tail of a few per cent), where every raw sample weighed at the raw scatter
    gives it three times too small."""
    from cpas_ocp.io.log_noise import block_sigma, correlation_length, independent_blocks
    t = np.arange(20000) * 0.01
    trend = 3000.0 - 20.0 * t
    for seed in range(10):
        white = np.random.default_rng(seed).normal(0.0, 2.0, t.size)
        assert correlation_length(t, trend + white) == 1, seed
    a = 0.8
    truth = np.sqrt(1.0 / (1.0 - a**2)) * np.sqrt((1.0 + a) / (1.0 - a) / t.size)
    for seed in (42, 43, 44):
        e = np.random.default_rng(seed).normal(0.0, 1.0, t.size)
        ar = np.empty(t.size)
        ar[0] = e[0]
        for k in range(1, t.size):
            ar[k] = a * ar[k - 1] + e[k]
        assert 7 <= correlation_length(t, trend + ar) <= 11
        blocks, size = independent_blocks(pd.DataFrame({"time": t, "altitude": trend + ar}))
        assert len(blocks) == int(np.ceil(t.size / size))
        assert block_sigma(blocks) / np.sqrt(len(blocks)) == pytest.approx(truth, rel=0.15)
        assert np.std(ar) / np.sqrt(t.size) < truth / 2.5


def test_still_air_leaves_the_air_motion_out_of_the_default(flight: Flight,
                                                            tmp_path: Path) -> None:
    """`import --still-air` writes the rocket default without the wind process; a card's own
    model is written as it is either way."""
    from tests.io.test_rocket_log_import import COLUMN_MAP
    write_mapped(flight, tmp_path / "log.csv", seed=18)
    card = {k: v for k, v in CARD.items() if k != "model"}
    args = ["import", str(tmp_path / "log.csv"), "--columns",
            _write(tmp_path, "map.json", COLUMN_MAP), "--card",
            _write(tmp_path, "card.json", card)]
    assert main([*args, "--out", str(tmp_path / "still"), "--still-air"]) == 0
    assert main([*args, "--out", str(tmp_path / "air")]) == 0

    def effects(folder: str) -> list[str]:
        model = json.loads((tmp_path / folder / "manifest.json").read_text())["model"]
        return [e if isinstance(e, str) else e["effect"] for e in model["effects"]]

    assert "wind_process" not in effects("still") and "wind_process" in effects("air")
    assert set(effects("air")) - set(effects("still")) == {"wind_process"}


def test_a_log_sampled_at_4_khz_keeps_its_events_sigmas(tmp_path: Path) -> None:
    """A 4 kHz logger: each detected event's sigma is its sample interval, 0.25 ms, which the
    manifest states (rounded to the millisecond it read 0, which no test folder may hold, and
    the import blamed the card); the event times keep the sample's resolution."""
    rate = 4000.0
    coarse = fly(rate_hz=500.0)
    t = np.arange(coarse.t[0], coarse.t[-1], 1.0 / rate)
    fast = Flight(t, np.interp(t, coarse.t, coarse.h), np.interp(t, coarse.t, coarse.v),
                  np.interp(t, coarse.t, coarse.f), coarse.events)
    p, a = sensor_readings(fast, 8)
    pd.DataFrame({"t": np.round(t, 6), "p": np.round(p, 1), "acc": np.round(a, 3)}).to_csv(
        tmp_path / "log.csv", index=False)
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, CARD)
    assert code == 0 and report is not None
    test = load_test(tmp_path / "test")
    charges = {e.parachute: e for e in test.events if e.name == "mortar_fire"}
    for name in ("drogue", "main"):
        assert charges[name].sigma == pytest.approx(1.0 / rate, rel=1e-3), name
        assert charges[name].time == pytest.approx(
            report["flight_events"][name]["time_s"], abs=1e-6), name


def _mistaken(flight: Flight, seed: int) -> dict[str, tuple[pd.DataFrame, dict, str, str]]:
    """Logs of the flight read through a map that mistakes a unit or a column: (table, map,
    the column the one line names, the question it asks)."""
    table = _table(flight, seed)
    feet = pd.DataFrame({"t": table["t"], "alt": np.round(
        np.asarray(pressure_altitude(table["p"].to_numpy()), float) / FT, 1)})
    with_gravity = table.assign(acc=np.round((table["acc"] + G0) / 1.0, 3))
    return {
        "altitude in ft declared m": (
            feet, {"time": AXIAL_MAP["time"], "altitude": {"column": "alt", "unit": "m"}},
            "altitude column 'alt'", "is the unit ft, not m?"),
        "pressure in hPa declared Pa": (
            table.assign(p=np.round(table["p"] / 100.0, 3)), AXIAL_MAP,
            "pressure column 'p'", "is the unit hPa, not Pa?"),
        "time in s declared ms": (
            table, {**AXIAL_MAP, "time": {"column": "t", "unit": "ms"}},
            "time column 't'", "is the unit s, not ms?"),
        "acceleration in m/s^2 declared g": (
            with_gravity, {**AXIAL_MAP, "acceleration": {"column": "acc", "unit": "g"}},
            "acceleration column 'acc'", "is the unit m/s^2, not g?"),
        "an accelerometer axis with its sign reversed": (
            table, {**AXIAL_MAP, "acceleration": {**AXIAL_MAP["acceleration"], "sign": -1}},
            "acceleration column 'acc'", "is its sign reversed"),
        "the pressure's column named as the acceleration's": (
            table, {**AXIAL_MAP, "acceleration": {"column": "p", "unit": "m/s^2"}},
            "acceleration column 'p'", "right column"),
    }


@pytest.mark.parametrize("case", ["altitude in ft declared m", "pressure in hPa declared Pa",
                                  "time in s declared ms", "acceleration in m/s^2 declared g",
                                  "an accelerometer axis with its sign reversed",
                                  "the pressure's column named as the acceleration's"])
def test_a_unit_mistake_is_named(case: str, flight: Flight, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Readings no flight makes (a pad at 3 K or 204 K, a descent at 30 km/s, 8.8 g under a
    canopy, a boost read at -4 g) are one line naming the log's column and asking about the
    unit (or sign) that would make them physical, exit 2, no folder; the same log in the
    right unit imports (the first test of this module)."""
    table, column_map, column, question = _mistaken(flight, 9)[case]
    table.to_csv(tmp_path / "log.csv", index=False)
    code, _, err = _import(tmp_path, tmp_path / "log.csv", column_map, CARD, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert "log.csv" in lines[0] and column in lines[0] and question in lines[0], lines[0]
    assert not (tmp_path / "test").exists()


def test_the_card_pressure_of_another_unit_is_the_cards_mistake(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A card whose site.pressure is in hPa but says Pa (863 Pa, 3 K with its surface
    density) names the card's field, not the log."""
    _table(flight, 10).to_csv(tmp_path / "log.csv", index=False)
    card = {**CARD, "site": {**CARD["site"], "pressure": {"value": 863, "unit": "Pa"}}}
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card, capsys)
    assert code == 2 and "card.json: site.pressure" in err, err


def test_a_card_with_fewer_canopies_than_charges_is_one_line(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The log shows two ejection charges; a card with the drogue only would fit the main's
    opening with no canopy to make it: one line naming the card's parachutes and the
    charge's time."""
    _table(flight, 11).to_csv(tmp_path / "log.csv", index=False)
    card = {**CARD, "parachutes": CARD["parachutes"][:1]}
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert "card.json: parachutes" in lines[0] and "ejection charge" in lines[0]
    assert f"{sample_time(flight, flight.events['main']):.2f} s" in lines[0]


def test_a_card_event_after_the_log_ends_is_the_cards(
        flight: Flight, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A card's main at 5000 s on a log of 80 s: the card's field is named (the manifest's
    check named the log as if it had written the time)."""
    _without_main_charge(flight, 12).to_csv(tmp_path / "log.csv", index=False)
    card = {**CARD, "events": {"main": {"time": {"value": 5000, "unit": "s"},
                                        "sigma": {"value": 0.5, "unit": "s"}}}}
    code, _, err = _import(tmp_path, tmp_path / "log.csv", AXIAL_MAP, card, capsys)
    assert code == 2 and "card.json: events.main.time" in err, err


def test_a_short_log_takes_the_accelerometers_rest_from_its_pad(flight: Flight,
                                                                 tmp_path: Path) -> None:
    """A log cut 20 s before touchdown lasts 43 s, 2 s of them on the pad: its first tenth
    reaches 2.3 s into the boost, and a rest taken there read the boost's axis with the
    wrong sign (refused as "is its sign reversed?").  The rest is the pad's, where the
    specific force is 1 g: the axis is -y, as the log was written."""
    from tests.io.test_rocket_log_import import COLUMN_MAP
    write_mapped(flight, tmp_path / "log.csv", seed=3,
                 end_s=flight.events["landed"] - 20.0)
    code, report, _ = _import(tmp_path, tmp_path / "log.csv", COLUMN_MAP, CARD)
    assert code == 0 and report is not None
    assert "axial accelerometer axis: -y" in report["notes"]
