"""A log's damaged end and a charge's filtered swing are left out; an impact, a landing, a
ballistic fall and a canopy's opening are not (`cpas_ocp.io.log_hygiene`), and the
import of a log with garbage at its end fits what the flight made."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import fly
from cpas_ocp.io.log_hygiene import charge_swing, damaged_end, turned_over
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped

NOISE_M = 0.5


def _descent(rate_m_s: float, seconds: float, hz: float, seed: int, top: float = 1200.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """A steady descent at `rate_m_s` (m/s, > 0) sampled at `hz`, with white noise."""
    t = np.arange(0.0, seconds, 1.0 / hz)
    rng = np.random.default_rng(seed)
    return t, top - rate_m_s * t + rng.normal(0.0, NOISE_M, t.size)


@pytest.mark.parametrize("seed", range(5))
def test_garbage_at_the_end_is_cut_to_the_end(seed: int) -> None:
    """Two samples that fall hundreds of metres in half a second from a 6 m/s descent: no
    descent falls so, and nothing after returns to the flight."""
    t, h = _descent(6.0, 60.0, 2.0, seed)
    h[-2:] = [h[-3] - 216.0, h[-3] - 391.0]
    damage = damaged_end(t, h)
    assert damage is not None and damage.to_end
    assert damage.t_from == t[-2] and damage.rows.tolist() == [t.size - 2, t.size - 1]


@pytest.mark.parametrize("seed", range(5))
def test_a_clean_end_is_kept(seed: int) -> None:
    """A descent at 25 m/s that lands and rests, a ballistic fall at 90 m/s to the log's end,
    and a descent that ends in the air: all flight."""
    t, h = _descent(25.0, 40.0, 100.0, seed)
    ground = t >= 40.0 - 3.0
    h[ground] = h[~ground][-1] + np.random.default_rng(seed).normal(0, NOISE_M, ground.sum())
    assert damaged_end(t, h) is None
    assert damaged_end(*_descent(90.0, 30.0, 20.0, seed, top=3000.0)) is None
    assert damaged_end(*_descent(6.0, 300.0, 2.0, seed)) is None


def test_a_1_khz_log_s_noise_is_no_damage() -> None:
    """At 1 kHz, 0.3 m of noise reads 420 m/s from one sample to the next, faster than any
    canopy descends: noise, not a damaged end (it was reported as one of no samples)."""
    t = np.arange(0.0, 20.0, 1e-3)
    for seed in range(5):
        h = 1200.0 - 6.0 * t + np.random.default_rng(seed).normal(0.0, 0.3, t.size)
        assert damaged_end(t, h) is None, seed


def test_an_impact_pulse_before_the_ground_is_cut_alone() -> None:
    """One sample of an impact's pressure pulse, then the vehicle rests on the ground: only
    the pulse is not flight."""
    t, h = _descent(25.0, 40.0, 100.0, 1)
    ground = t >= 38.0
    h[ground] = h[~ground][-1]
    k = int(np.flatnonzero(ground)[0])
    h[k] -= 80.0
    damage = damaged_end(t, h)
    assert damage is not None and not damage.to_end and damage.rows.tolist() == [k]


def test_a_filtered_charge_swing_is_found_and_an_opening_is_not() -> None:
    """A recorder's filter spreads a charge's pulse into a 740 m dive over 1.3 s: the swing
    spans it.  A main's opening (25 to 6 m/s in a second) bends the altitude by metres: no
    swing."""
    t, h = _descent(25.0, 30.0, 100.0, 2, top=3500.0)
    dive = (t >= 10.0) & (t <= 11.3)
    h[dive] -= 740.0 * np.sin(np.pi * (t[dive] - 10.0) / 1.3)
    span = charge_swing(t, h, 10.0)
    assert span is not None and span[0] <= 10.1 and span[1] >= 11.1
    v = np.where(t < 10.0, 25.0, np.maximum(6.0, 25.0 - 19.0 * (t - 10.0)))
    h_open = 3500.0 - np.cumsum(v) / 100.0 + np.random.default_rng(3).normal(0, NOISE_M, t.size)
    assert charge_swing(t, h_open, 10.0) is None


def _imported(folder: Path) -> dict:
    """`folder`'s log.csv imported in still air through the standard map (its axial axis
    -y) and card into `folder`/test; the import report."""
    accel = {**COLUMN_MAP["acceleration"], "axis": "-y"}
    (folder / "map.json").write_text(json.dumps({**COLUMN_MAP, "acceleration": accel}))
    (folder / "card.json").write_text(json.dumps(CARD))
    assert main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                 "--card", str(folder / "card.json"), "--out", str(folder / "test"),
                 "--still-air"]) == 0
    return json.loads((folder / "test" / "import.json").read_text())


def test_a_log_with_garbage_at_its_end_imports_without_it(tmp_path: Path) -> None:
    """A mapped log whose last two rows read 300 m below the descent (a recorder writing its
    buffer out badly) imports, says so, and writes no altimeter sample after the damage."""
    flight = fly()
    write_mapped(flight, tmp_path / "log.csv", seed=4, end_s=flight.events["landed"] - 20.0)
    log = pd.read_csv(tmp_path / "log.csv")
    log.loc[log.index[-2:], "press_hPa"] += 35.0  # about 300 m lower
    log.to_csv(tmp_path / "log.csv", index=False, float_format="%.7g")
    report = _imported(tmp_path)
    assert report["dropped"]["damaged_end_samples"] == 2
    assert any("left out: no descent falls that way" in n for n in report["notes"])
    t_damage = 1e-3 * float(log["t_ms"].iloc[-2])
    baro = pd.read_csv(tmp_path / "test" / "baro.csv")
    assert baro["time"].max() < t_damage


def test_a_body_that_turns_over_is_found_and_a_swinging_one_is_not() -> None:
    """A rocket hanging under its drogue reads +8 m/s^2 along its axis with a swing of
    3 m/s^2; for 5 s it tumbles and reads -15: those samples (and half a second about them)
    are found, the swing's troughs are not."""
    t = np.arange(0.0, 60.0, 0.01)
    rng = np.random.default_rng(7)
    force = 8.0 + 3.0 * np.sin(2 * np.pi * t / 1.7) + rng.normal(0.0, 1.0, t.size)
    assert not turned_over(t, force).any()
    tumble = (t >= 30.0) & (t < 35.0)
    force[tumble] = -15.0 + rng.normal(0.0, 1.0, tumble.sum())
    over = turned_over(t, force)
    assert over[tumble].all()
    assert not over[(t < 29.4) | (t > 35.6)].any()


def test_a_body_falling_free_is_not_turned_over() -> None:
    """Near apogee nothing pulls: the axis reads zero with its noise and a small offset,
    whose half-second medians dip below zero by chance; that is no tumble."""
    t = np.arange(0.0, 30.0, 0.01)
    force = -0.3 + np.random.default_rng(8).normal(0.0, 2.0, t.size)
    assert not turned_over(t, force).any()


def test_a_glitch_under_the_canopies_is_named_a_transient_not_a_unit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """0.6 s of samples 600 m off in the middle of the main's descent: the import stops, as
    no canopy descends at such rates, but names a transient, not a unit the steady flight
    does not support."""
    flight = fly()
    write_mapped(flight, tmp_path / "log.csv", seed=4)
    log = pd.read_csv(tmp_path / "log.csv")
    mid = int(np.argmin(np.abs(1e-3 * log["t_ms"].to_numpy() - 45.0)))
    log.loc[mid:mid + 59, "press_hPa"] += 70.0  # about 600 m lower for 0.6 s
    log.to_csv(tmp_path / "log.csv", index=False, float_format="%.7g")
    accel = {**COLUMN_MAP["acceleration"], "axis": "-y"}
    (tmp_path / "map.json").write_text(json.dumps({**COLUMN_MAP, "acceleration": accel}))
    (tmp_path / "card.json").write_text(json.dumps(CARD))
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(tmp_path / "card.json"), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "a transient" in err[0] and "is the unit" not in err[0]


def test_the_rate_before_each_sample_is_the_least_squares_slope_over_its_window() -> None:
    """The running sums give np.polyfit's slope over every window, on a clock far from zero
    and a noisy descent at 1 kHz, and count the samples each window holds."""
    from cpas_ocp.io.log_hygiene import RATE_BEFORE_S, rates_before

    rng = np.random.default_rng(5)
    t = 86_400.0 + np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 9000))
    h = 3000.0 - 25.0 * (t - t[0]) + rng.normal(0.0, 0.3, t.size)
    ends = np.arange(2, t.size, 97)
    count, rate = rates_before(t, h, ends)
    for e, n, r in zip(ends, count, rate, strict=True):
        window = (t >= t[e] - RATE_BEFORE_S) & (t <= t[e])
        assert n == window.sum()
        expected = np.polyfit(t[window] - t[e], h[window], 1)[0]
        assert r == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_a_log_whose_body_tumbles_under_its_canopies_says_where(tmp_path: Path) -> None:
    """A mapped log whose axial accelerometer reads -1.5 g for 4 s under the canopies (the
    body tumbling: its specific force reversed) imports with that stretch in its report
    and a note; the samples stay in the folder."""
    flight = fly()
    write_mapped(flight, tmp_path / "log.csv", seed=4)
    log = pd.read_csv(tmp_path / "log.csv")
    t = 1e-3 * log["t_ms"].to_numpy()
    t_tumble = flight.events["drogue"] + 20.0
    tumble = (t >= t_tumble) & (t < t_tumble + 4.0)
    rng = np.random.default_rng(9)
    log.loc[tumble, "ay_g"] = np.round(1.5 + rng.normal(0.0, 0.05, tumble.sum()), 4)  # -1.5 g
    log.to_csv(tmp_path / "log.csv", index=False, float_format="%.7g")
    report = _imported(tmp_path)
    [(first, last)] = report["turned_over_s"]
    assert t_tumble - 0.6 <= first <= t_tumble + 0.1
    assert t_tumble + 3.9 <= last <= t_tumble + 4.6
    assert any(n.startswith("the body turned over from") for n in report["notes"])


def test_a_clean_flight_has_no_turned_over_stretch(tmp_path: Path) -> None:
    """The same flight without the tumble: its boost, coast, charges and openings are no
    turned-over stretch."""
    flight = fly()
    write_mapped(flight, tmp_path / "log.csv", seed=4)
    report = _imported(tmp_path)
    assert report["turned_over_s"] == []
