"""Touchdown where the altitude stops descending and stays at the ground's level.

The seeded generator of `cpas_ocp/io/example_flight.py` flies the rocket to a ground
7 m above the pad; the log is sampled from 1 Hz to 1 kHz and cut seconds after the
touchdown, or in the air.  A log whose last seconds lie still on the ground is landed
(within three of the sigmas it states of the true touchdown, the phase ending before it);
a log that ends in the air is not.  A flight computer's filtered altitude
(`recovery_flights.filtered_altitude`) overshoots below the ground at the impact and
rebounds metres above it: the descent ends where it first reaches the ground, not after
the rebound.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.io.example_flight import GROUND_M, Flight, fly, sensor_readings
from cpas_ocp.io.flight_events import detect_events, level_noise, second_difference_sigma
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.atmosphere import pressure_altitude
from tests.io.recovery_flights import filtered_altitude
from tests.io.test_rocket_log_import import COLUMN_MAP, _card, _import, write_mapped

REST_S = 2.7  # a real log kept 2.7 s of the vehicle at rest after its touchdown


@cache
def _flight_at(rate_hz: float, seconds_after_touchdown: float) -> Flight:
    """The flight logged at `rate_hz` (above 500 Hz: the 500 Hz truth interpolated)."""
    coarse = fly(seconds_after_touchdown=seconds_after_touchdown,
                 rate_hz=min(rate_hz, 500.0))
    if rate_hz <= 500.0:
        return coarse
    t = np.arange(coarse.t[0], coarse.t[-1], 1.0 / rate_hz)
    return Flight(t, np.interp(t, coarse.t, coarse.h), np.interp(t, coarse.t, coarse.v),
                  np.interp(t, coarse.t, coarse.f), coarse.events)


def _samples(flight: Flight, seed: int, altitude: np.ndarray | None = None,
             end_s: float = np.inf) -> pd.DataFrame:
    """The record's samples (time s, pressure altitude m, axial reading m/s^2) up to
    `end_s`: the altimeter's readings, or `altitude` where given."""
    p, a = sensor_readings(flight, seed)
    h = np.asarray(pressure_altitude(p), dtype=float) if altitude is None else altitude
    keep = flight.t <= end_s
    return pd.DataFrame({"time": flight.t[keep], "altitude": h[keep],
                         "acceleration": a[keep]})


@pytest.mark.parametrize("rate_hz, rest_s", [(1.0, REST_S), (10.0, REST_S), (100.0, REST_S),
                                             (1000.0, REST_S), (100.0, 1.2)])
def test_a_log_resting_briefly_on_the_ground_is_landed(rate_hz: float, rest_s: float) -> None:
    """The log ends `rest_s` after the touchdown, the altitude flat at the ground's level:
    landed within three of its stated sigmas of the truth, a sigma of a sample interval
    or a few (not the log's end)."""
    flight = _flight_at(rate_hz, rest_s + 0.5)
    truth = flight.events["landed"]
    for seed in range(3):
        events, _ = detect_events(_samples(flight, seed, end_s=truth + rest_s))
        assert "landed" in events, (rate_hz, seed)
        landed = events["landed"]
        assert abs(landed.time - truth) <= 3.0 * landed.sigma, (rate_hz, seed)
        assert landed.sigma <= max(1.0 / rate_hz, 0.05) + 1e-9, (rate_hz, seed)


@pytest.mark.parametrize("rate_hz", [1.0, 10.0, 100.0, 1000.0])
@pytest.mark.parametrize("above_m", [3.0, 30.0])
def test_a_log_ending_in_the_air_is_not_landed(rate_hz: float, above_m: float) -> None:
    """A log cut while the vehicle is still `above_m` over the ground finds no touchdown."""
    flight = _flight_at(rate_hz, 1.0)
    end = float(flight.t[np.flatnonzero((flight.h <= GROUND_M + above_m)
                                        & (flight.t > flight.events["apogee"]))[0]])
    for seed in range(3):
        events, _ = detect_events(_samples(flight, seed, end_s=end))
        assert "landed" not in events, (rate_hz, above_m, seed)


def test_a_filtered_altitude_s_rebound_is_not_the_descent() -> None:
    """A filtered export (100 Hz) overshoots metres below the ground at the impact and
    rebounds above it by more than the noise's margin: touchdown is where the descent
    first reaches the ground, within three of its sigmas of the truth, not after the
    rebound (the last sample above the ground, 2.9 s late)."""
    flight = _flight_at(100.0, 10.0)
    truth = flight.events["landed"]
    for seed in range(3):
        z = np.asarray(pressure_altitude(sensor_readings(flight, seed)[0]), dtype=float)
        h = filtered_altitude(flight.t, z)
        # The pathology is there: an overshoot below the ground and a rebound above it.
        ground = float(np.median(h[flight.t > truth + 6.0]))
        after = (flight.t > truth) & (flight.t < truth + 4.0)
        assert ground - h[after].min() > 2.0
        assert h[after & (flight.t > truth + 1.0)].max() - ground > 1.0
        landed = detect_events(_samples(flight, seed, altitude=h))[0]["landed"]
        assert abs(landed.time - truth) <= max(3.0 * landed.sigma, 0.03), seed


def test_level_noise_reads_a_filtered_channel_s_scatter() -> None:
    """White noise reads the same at every lag; a filtered, quantised channel at rest reads
    a fraction of its scatter one sample apart, and about its scatter at the lags its
    filter decorrelates over."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 30.0, 0.01)
    white = rng.normal(0.0, 0.3, t.size)
    assert level_noise(t, white) == pytest.approx(0.3, rel=0.1)
    still = filtered_altitude(t, 100.0 + rng.normal(0.0, 1.0, t.size), omega=8.0, zeta=0.7)
    scatter = float(np.std(still[t > 5.0]))
    assert second_difference_sigma(still[t > 5.0]) < 0.5 * scatter
    assert level_noise(t[t > 5.0], still[t > 5.0]) == pytest.approx(scatter, rel=0.35)


def test_a_brief_rest_imports_landed_and_the_phase_ends_before_it(tmp_path: Path) -> None:
    """A column-mapped log that ends 1.2 s after its touchdown: the import finds touchdown
    (not `the log ends`), and the phase ends before the true touchdown."""
    flight = fly()
    truth = flight.events["landed"]
    write_mapped(flight, tmp_path / "log.csv", seed=6, end_s=truth + 1.2)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    report = _import(["import", str(tmp_path / "log.csv"), "--columns",
                      str(tmp_path / "map.json"), "--card", str(_card(tmp_path))],
                     tmp_path / "test")
    landed = report["flight_events"]["landed"]
    assert abs(landed["time_s"] - truth) <= 3.0 * landed["sigma_s"]
    assert any(n.startswith("touchdown at") for n in report["notes"])
    assert load_test(tmp_path / "test").t_end < truth
