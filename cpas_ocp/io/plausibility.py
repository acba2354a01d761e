"""Physical limits a flight log's readings meet, whatever the rocket: a log that breaks one
holds a unit mistake or the wrong column, and is named as such (one line, exit 2) rather
than imported into a folder whose fit would mean nothing.

* speed: the altitude's rate of change, robust to the ejection charges' one-sample pressure
  pulses (the running median over `SPEED_WINDOW_S`, at least `MEDIAN_SAMPLES` samples, and
  its change over as long), at most `MAX_SPEED_M_S` anywhere (5 km/s: beyond any amateur
  or sounding rocket in the lower atmosphere) and `MAX_DESCENT_M_S` under the canopies
  (400 m/s: no canopy descends faster; a rocket falls under a drogue at tens of m/s).  A
  time column in s declared ms makes a 30 m/s descent 30 km/s;
* the pad's air: its pressure within `PAD_PRESSURE_PA` (30-110 kPa: a pad 9 km up to one
  below the Dead Sea, in any weather), the temperature it gives with the card's surface
  density (T = p / (R rho)) within `PAD_TEMPERATURE_K` (180-340 K), and its pressure
  altitude within `MAX_PAD_OFFSET_M` of the card's site elevation (weather moves it by a
  few hundred metres).  A pressure in hPa declared Pa gives 1013 Pa and 3 K; an altitude in
  ft declared m gives the pad 3.3 times as high, 57 kPa and 204 K at a 1400 m site;
* the boost: where the altimeter climbs faster than `BOOST_CLIMB_M_S` (50 m/s, which
  only thrust gives), the axial accelerometer reads the thrust in the `BOOST_WINDOW_S`
  before, above `MIN_BOOST_G` (1 g subtracted: a thrust twice the weight, below any safe
  launch's).  An axis whose sign is reversed, whose reading turned over shows a boost,
  is named;
* the accelerometer under the canopies: the drag carries the weight, so the specific
  force along the body is about one g (less as the body swings or hangs sideways), and
  the median axial reading (1 g subtracted) lies within `MAX_STEADY_G` of zero.  A reading
  in m/s^2 declared g, or the pressure's column named as the acceleration's, does not.

Each error names the log, the column and what was expected, and asks about the unit that
would make the readings physical where one of the column's kind does
(`flight_record.Channel.hint`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_events import BOOST_G, BOOST_RUN
from cpas_ocp.io.flight_record import FlightRecord, pressure_of_altitude
from cpas_ocp.physics.atmosphere import pressure_altitude
from cpas_ocp.physics.units import G0

MAX_SPEED_M_S = 5000.0  # no rocket climbs or falls faster in the lower atmosphere (m/s)
MAX_DESCENT_M_S = 400.0  # no vehicle descends faster under a canopy (m/s)
SPEED_WINDOW_S = 0.5  # the altitude's running median and its change span this long (s) ...
MEDIAN_SAMPLES = 9  # ... and at least this many samples (a charge's pulse is 1-3)
STEADY_SPEED_S = 3.0  # a unit hint needs the rate over this long beyond the ceiling too (s)
PAD_PRESSURE_PA = (30e3, 110e3)  # air pressure on any launch pad (Pa)
PAD_TEMPERATURE_K = (180.0, 340.0)  # air temperature on any launch pad (K)
MAX_PAD_OFFSET_M = 2000.0  # the pad's pressure altitude off the site's elevation (m)
MAX_STEADY_G = 3.0  # median axial reading under the canopies, off zero (g)
BOOST_CLIMB_M_S = 50.0  # a climb this fast is a boost's (m/s): no canopy climbs ...
BOOST_WINDOW_S = 10.0  # ... whose thrust the accelerometer reads in this long before (s) ...
MIN_BOOST_G = 1.0  # ... above this (g, 1 g subtracted: a thrust twice the weight)


def climb_rates(t: np.ndarray, h: np.ndarray, window_s: float = SPEED_WINDOW_S
                ) -> tuple[np.ndarray, np.ndarray]:
    """The rate of climb (m/s, negative in a descent) of the altitude `h` (m) at times `t` (s,
    increasing), robust to short pulses, and the times it applies from: the change of the
    running median over `window_s` (at least `MEDIAN_SAMPLES` samples, at most an
    eighth of the log) across as many samples, so that a pulse of a few samples (an
    ejection charge's gas at the static port) does not count.  Empty for under 2 samples."""
    if t.size < 2:
        return np.empty(0), np.empty(0)
    interval = float(np.median(np.diff(t)))
    n = max(MEDIAN_SAMPLES, round(window_s / interval) if interval > 0 else 0)
    # An eighth of the log at most: a log whose time unit is off by 1000 spans milliseconds.
    n = min(n, max(MEDIAN_SAMPLES, t.size // 8)) // 2 * 2 + 1
    n = min(n, t.size - 1)
    smooth = pd.Series(h).rolling(n, center=True, min_periods=1).median().to_numpy()
    return (smooth[n:] - smooth[:-n]) / (t[n:] - t[:-n]), t[:-n]


def peak_speed(t: np.ndarray, h: np.ndarray, window_s: float = SPEED_WINDOW_S
               ) -> tuple[float, float]:
    """The largest rate of change (m/s) of the altitude `h` (m) at times `t` (s), either way
    (`climb_rates` over `window_s`), and its time."""
    rate, at = climb_rates(t, h, window_s)
    if rate.size == 0:
        return 0.0, float(t[0]) if t.size else 0.0
    k = int(np.argmax(np.abs(rate)))
    return float(abs(rate[k])), float(at[k])


def check_speed(record: FlightRecord, t: np.ndarray, h: np.ndarray, ceiling: float,
                what: str) -> None:
    """InputError naming the log's time and altimeter columns where the altitude `h` (m) at
    times `t` (s) changes faster than `ceiling` (m/s; `what` says whose limit it is)."""
    speed, at = peak_speed(t, h)
    if speed <= ceiling:
        return
    time, baro = record.channel("time"), record.channel("pressure")
    # A unit scales the steady flight's rates, not only a transient's: where the rate over
    # STEADY_SPEED_S stays within the ceiling, the excess is a pulse or a glitch.
    if peak_speed(t, h, STEADY_SPEED_S)[0] <= ceiling:
        hint = ("a transient: over 3 s the altitude keeps to a flight's rates, so this is a "
                "pressure pulse or a glitch in the log, not its unit")
    else:
        hint = time.hint(lambda unit: speed / time.reread(1.0, unit) <= ceiling)
        if not hint.startswith("is the unit") and baro.altitude:
            hint = baro.hint(lambda unit: speed * baro.reread(1.0, unit) <= ceiling)
    raise InputError(str(record.path), f"{time.column}, {baro.column}",
                     f"an altitude that changes at most {ceiling:g} m/s ({what}); read in "
                     f"{baro.unit} and {time.unit}, it changes at {speed:.4g} m/s near "
                     f"{at:.2f} s: {hint}")


def check_pad_air(record: FlightRecord, p0: float, t0: float, temperature_from: str,
                  elevation: float, card_source: str, pressure_from_card: bool = False
                  ) -> None:
    """InputError where the pad's pressure `p0` (Pa, the log's), the temperature `t0` (K)
    and the site's `elevation` (m) are not those of air on a launch pad (see the module
    docstring).  `temperature_from` is ``"density"`` where `t0` is p0 / (R rho) with the
    card's surface density, ``"card"`` where the card gives it, ``"standard"`` otherwise.
    A temperature or pressure the card gives (`pressure_from_card`) is the card's mistake;
    anything else, the log's pressure (or altitude) column, asked about the unit that
    would make it physical."""
    low_t, high_t = PAD_TEMPERATURE_K
    if temperature_from == "card" and not low_t <= t0 <= high_t:
        raise InputError(card_source, "site.temperature", f"a pad temperature of "
                         f"{low_t:g}-{high_t:g} K; got {t0:.1f} K")
    if _pad_air_ok(p0, t0, temperature_from, elevation):
        return
    baro = record.channel("pressure")

    def as_read_in(unit: str) -> float:
        """The pad's pressure (Pa) had the column been in `unit`."""
        if baro.altitude:
            return float(pressure_of_altitude(
                np.array([baro.reread(float(pressure_altitude(p0)), unit)]))[0])
        return baro.reread(p0, unit)

    hint = baro.hint(lambda unit: _pad_air_ok(as_read_in(unit), t0 * as_read_in(unit) / p0
                                              if temperature_from == "density" else t0,
                                              temperature_from, elevation))
    if pressure_from_card:
        hint = "check the card's site block"
    elif not hint.startswith("is the unit"):
        hint += (" (or the card's site.surface_density?)" if temperature_from == "density"
                 else " (or the card's site.elevation?)")
    gives = f"a pad pressure of {p0:.0f} Pa" + (f" and a pad temperature of {t0:.0f} K"
                                                if temperature_from == "density" else "")
    low_p, high_p = PAD_PRESSURE_PA
    raise InputError(*((card_source, "site.pressure") if pressure_from_card
                       else (str(record.path), baro.column)),
                     f"the air of a launch pad ({1e-3 * low_p:g}-{1e-3 * high_p:g} kPa, "
                     f"{low_t:g}-{high_t:g} K, at a pressure altitude within "
                     f"{MAX_PAD_OFFSET_M:g} m of the card's site elevation {elevation:.0f} m); "
                     f"it gives {gives}, the standard atmosphere's at "
                     f"{float(pressure_altitude(p0)):.0f} m: {hint}")


def _pad_air_ok(p0: float, t0: float, temperature_from: str, elevation: float) -> bool:
    """Whether pressure `p0` (Pa) and temperature `t0` (K) are a launch pad's air at
    `elevation` (m): `PAD_PRESSURE_PA`, `PAD_TEMPERATURE_K` (where the temperature comes from
    the pressure) and `MAX_PAD_OFFSET_M`."""
    low_p, high_p = PAD_PRESSURE_PA
    low_t, high_t = PAD_TEMPERATURE_K
    return bool(low_p <= p0 <= high_p
                and (temperature_from != "density" or low_t <= t0 <= high_t)
                and abs(float(pressure_altitude(p0)) - elevation) <= MAX_PAD_OFFSET_M)


def check_steady_accelerometer(record: FlightRecord, a: np.ndarray) -> None:
    """InputError naming the log's acceleration column where the median of its axial
    readings `a` (m/s^2, 1 g subtracted) under the canopies lies further than
    `MAX_STEADY_G` from zero (see the module docstring)."""
    if a.size == 0:
        return
    median = float(np.median(a))
    if abs(median) <= MAX_STEADY_G * G0:
        return
    accel = record.channel("acceleration")
    hint = accel.hint(lambda unit: abs(accel.reread(median, unit)) <= MAX_STEADY_G * G0)
    raise InputError(str(record.path), accel.column,
                     f"a median axial reading within {MAX_STEADY_G:g} g of zero under the "
                     f"canopies (1 g subtracted: their drag carries the weight); it reads "
                     f"{median / G0:.4g} g there: {hint}")


def check_boost(record: FlightRecord, samples: pd.DataFrame) -> None:
    """InputError naming the log's acceleration column where the altimeter shows a boost (a
    climb faster than `BOOST_CLIMB_M_S`, which only thrust gives) and the axial
    accelerometer, reading over the `BOOST_WINDOW_S` before the fastest climb, reads the
    thrust with its sign reversed: never above `MIN_BOOST_G` (1 g subtracted: a
    thrust-to-weight ratio of 2, below any safe launch's), but, turned over (``sign`` -1,
    an axis ``"-y"``), a boost as `flight_events` detects one (above `BOOST_G` for
    `BOOST_RUN` samples).  An accelerometer that reads no boost
    either way (a lateral axis, or one that did not log the boost) is left to the other
    checks.  `samples` are the record's."""
    baro = samples[["time", "altitude"]].dropna()
    rate, at = climb_rates(baro["time"].to_numpy(float), baro["altitude"].to_numpy(float))
    if rate.size == 0 or float(rate.max()) < BOOST_CLIMB_M_S:
        return
    t_climb = float(at[int(np.argmax(rate))])
    accel = samples[["time", "acceleration"]].dropna()
    boost = accel[(accel["time"] >= t_climb - BOOST_WINDOW_S) & (accel["time"] <= t_climb)]
    a = boost["acceleration"].to_numpy(float)
    if a.size < MEDIAN_SAMPLES or float(a.max()) > MIN_BOOST_G * G0:
        return
    channel = record.channel("acceleration")
    # Turned over: the specific force reversed, for a reading whose offset (one g) the
    # reader subtracted; a logger's own subtraction turns over with its axis.
    flipped = pd.Series(-(a + channel.offset) - channel.offset)
    if not float(flipped.rolling(BOOST_RUN).min().max()) > BOOST_G * G0:
        return  # no boost either way: an accelerometer that did not read it, not a sign
    raise InputError(str(record.path), channel.column,
                     f"an axial reading that shows the boost the altimeter shows (a climb "
                     f"at {float(rate.max()):.0f} m/s near {t_climb:.2f} s): above "
                     f"{MIN_BOOST_G:g} g (1 g subtracted) in the {BOOST_WINDOW_S:g} s before; "
                     f"it reads {float(a.min()) / G0:.3g} to {float(a.max()) / G0:.3g} g "
                     f"there: is its sign reversed (a 'sign' of -1, or the axis with "
                     f"'-')?")
