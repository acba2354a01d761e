"""Flight events found in a rocket's barometer and axial accelerometer.

Where a flight computer logged no flight states, `detect_events` finds them
in the `flight_record.FlightRecord`'s samples, each with its time (s) and
timing sigma (s):

* ``boost``: the first of `BOOST_RUN` accelerometer samples reading more than
  `BOOST_G` above the pad's reading (the motor lit); sigma one sample;
* ``coast`` (burnout): the first sample after that whose specific force is
  below zero (axial reading below -1 g: the drag exceeds what thrust is
  left); sigma one sample;
* ``apogee``: the highest point of the altimeter's running median over
  `SMOOTH_S`; sigma half the time it stays within the noise of the top;
* ``drogue``, ``main``: the ejection charges, in order.  A charge jolts the
  accelerometer (and the shock cord's snatch follows) and its gas puffs the
  static port, which reads a pressure pulse (tens of metres of altitude in a
  sample or two).  Samples further than `SPIKE_SIGMAS` robust sigmas (and at
  least `SPIKE_MIN_G`, or `PULSE_MIN_M` for the altimeter) off the running
  median over `SMOOTH_S` are spikes; spikes closer than `CLUSTER_GAP_S` are
  one charge (its opening's snatch included).  The charge is the first spike
  of either sensor; its sigma the larger of the sensor's sample interval and
  the two sensors' disagreement;
* ``landed`` (touchdown, `touchdown`): from when the altitude stops falling.

What cannot be found (no accelerometer, no boost in the log) is left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cpas_ocp.physics.units import G0

BOOST_G = 3.0  # a boost reads this many g above the pad's reading ...
BOOST_RUN = 3  # ... for this many samples in a row
SMOOTH_S = 1.0  # running-median window of the spike and apogee searches (s)
SPIKE_SIGMAS = 8.0  # a spike stands this many robust sigmas off the running median ...
SPIKE_MIN_G = 3.0  # ... and at least this far (g) for the accelerometer
PULSE_MIN_M = 5.0  # ... or this far (m of pressure altitude) for the altimeter
CLUSTER_GAP_S = 3.0  # spikes closer than this are one ejection (charge, then snatch)
AFTER_BURNOUT_S = 1.0  # charges are looked for from this long after burnout (s)
HOLD_S = 3.0  # landed: still for this long (s)
STILL_RATE_M_S = 0.5  # ... the altitude's slope within this (m/s)
STILL_BAND_SIGMAS = 6.0  # ... its range within this many noise sigmas (+ STILL_BAND_M)
STILL_BAND_M = 1.0
REST_ACCEL_M_S2 = 1.0  # ... and the accelerometer's scatter within this (or 3 pad sigmas)
IMPACT_WINDOW_S = 0.5  # the landing's impact is looked for this close to the baro's touchdown


@dataclass(frozen=True)
class FlightEvent:
    """A flight event: time (s), timing sigma (s), and what found it."""

    time: float
    sigma: float
    source: str


def second_difference_sigma(values: np.ndarray) -> float:
    """White-noise sigma of a smooth signal's samples: 1.4826 MAD of the second
    differences over sqrt(6) (the second difference of white noise has variance 6 s^2)."""
    d2 = np.diff(values, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def _interval(t: np.ndarray) -> float:
    """Median sample interval (s)."""
    return float(np.median(np.diff(t))) if t.size > 1 else float("nan")


def _running_median(t: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    n = max(3, round(window_s / _interval(t)) // 2 * 2 + 1)
    return pd.Series(x).rolling(n, center=True, min_periods=1).median().to_numpy()


def _spikes(t: np.ndarray, x: np.ndarray, floor: float, within: np.ndarray) -> np.ndarray:
    """Times of the samples `within` further than SPIKE_SIGMAS robust sigmas (there) and
    `floor` off the running median over SMOOTH_S (taken over the whole series, so that the
    search window's edges see both sides)."""
    if within.sum() < 10:
        return np.empty(0)
    r = (x - _running_median(t, x, SMOOTH_S))[within]
    scatter = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    return t[within][np.abs(r) > max(SPIKE_SIGMAS * scatter, floor)]


def detect_events(samples: pd.DataFrame) -> tuple[dict[str, FlightEvent], list[str]]:
    """The events of the module docstring found in a record's `samples` (time (s), altitude
    (m), acceleration (m/s^2, 1 g subtracted)), and notes on what could not be told."""
    accel = samples[["time", "acceleration"]].dropna()
    baro = samples[["time", "altitude"]].dropna()
    ta, a = accel["time"].to_numpy(float), accel["acceleration"].to_numpy(float)
    tb, h = baro["time"].to_numpy(float), baro["altitude"].to_numpy(float)
    events: dict[str, FlightEvent] = {}
    notes: list[str] = []
    dta, dtb = _interval(ta), _interval(tb)
    if ta.size > 20:
        rest = float(np.median(a[: max(10, ta.size // 20)]))
        high = pd.Series(a - rest > BOOST_G * G0).rolling(BOOST_RUN).sum().to_numpy()
        runs = np.flatnonzero(high >= BOOST_RUN)
        if runs.size:
            k = runs[0] - BOOST_RUN + 1
            events["boost"] = FlightEvent(float(ta[k]), dta, "accelerometer")
            after = np.flatnonzero((ta > ta[runs[0]]) & (a + G0 < 0.0))
            if after.size:
                events["coast"] = FlightEvent(float(ta[after[0]]), dta, "accelerometer")
    if "boost" not in events:
        notes.append("no boost found in the accelerometer: boost and burnout not detected")
    if tb.size < 20:
        notes.append("too few altimeter samples to find apogee and touchdown")
        return events, notes
    start = events["coast"].time if "coast" in events else tb[0]
    smooth = _running_median(tb, h, SMOOTH_S)
    up = tb >= start
    k_top = int(np.flatnonzero(up)[np.argmax(smooth[up])])
    noise = max(second_difference_sigma(h), 0.05)
    near_top = tb[up][np.abs(smooth[up] - smooth[k_top]) <= 2.0 * noise]
    events["apogee"] = FlightEvent(float(tb[k_top]),
                                   max(dtb, 0.5 * float(near_top.max() - near_top.min())),
                                   "altimeter")
    down = touchdown(tb, h, ta, a, float(tb[k_top]))
    t_stop = down.time - HOLD_S if down is not None else float(tb[-1])
    lo = start + (AFTER_BURNOUT_S if "coast" in events else 0.0)
    in_a, in_b = (ta >= lo) & (ta < t_stop), (tb >= lo) & (tb < t_stop)
    jolts = _spikes(ta, a, SPIKE_MIN_G * G0, in_a)
    pulses = _spikes(tb, h, PULSE_MIN_M, in_b)
    charges = _ejections(jolts, pulses, dta, dtb)
    for name, event in zip(("drogue", "main"), charges, strict=False):
        events[name] = event
    if len(charges) > 2:
        notes.append(f"{len(charges) - 2} more ejection-like disturbance(s) after the main's, "
                     f"at {', '.join(f'{e.time:.2f}' for e in charges[2:])} s: not used")
    if not charges:
        notes.append("no ejection charge found in the accelerometer or the altimeter")
    if down is not None:
        events["landed"] = down
    return events, notes


def _ejections(jolts: np.ndarray, pulses: np.ndarray, dta: float, dtb: float
               ) -> list[FlightEvent]:
    """One event per cluster of spikes (see the module docstring)."""
    marks = sorted([(t, "accelerometer") for t in jolts] + [(t, "altimeter") for t in pulses])
    clusters: list[list[tuple[float, str]]] = []
    for mark in marks:
        if clusters and mark[0] - clusters[-1][-1][0] <= CLUSTER_GAP_S:
            clusters[-1].append(mark)
        else:
            clusters.append([mark])
    out = []
    for cluster in clusters:
        first = {}
        for t, source in cluster:
            first.setdefault(source, t)
        t0, source = cluster[0]
        sigma = dta if source == "accelerometer" else dtb
        if len(first) == 2:
            sigma = max(sigma, abs(first["accelerometer"] - first["altimeter"]))
            source = "accelerometer and altimeter"
        out.append(FlightEvent(float(t0), float(sigma), source))
    return out


def touchdown(tb: np.ndarray, h: np.ndarray, ta: np.ndarray, a: np.ndarray,
              after: float) -> FlightEvent | None:
    """Touchdown after `after` (s), or None where the log ends before the vehicle is down.

    Landed: the altitude's slope within STILL_RATE_M_S and its range within
    STILL_BAND_SIGMAS noise sigmas (+ STILL_BAND_M) over HOLD_S, and the
    accelerometer's scatter there within REST_ACCEL_M_S2 (or three times the
    pad's).  The touchdown time is where the line through the last 2 s
    of the descent above the ground's noise meets the ground level (the median
    altitude while still); where the accelerometer shows the impact within
    IMPACT_WINDOW_S of it, the impact's sample.  Sigma: one sample interval of
    the sensor that timed it, or the noise over the descent rate."""
    noise = max(second_difference_sigma(h), 0.05)
    band = STILL_BAND_SIGMAS * noise + STILL_BAND_M
    rest_a = (max(REST_ACCEL_M_S2, 3.0 * float(np.std(a[: max(10, ta.size // 20)])))
              if ta.size > 20 else np.inf)
    dtb = _interval(tb)
    step = max(1, round(0.1 / dtb))
    candidates = np.flatnonzero(tb > after)[::step]
    for i in candidates:
        w = (tb >= tb[i]) & (tb <= tb[i] + HOLD_S)
        if tb[i] + HOLD_S > tb[-1] or w.sum() < 5:
            return None
        hw = h[w]
        if np.ptp(hw) > band or abs(np.polyfit(tb[w] - tb[i], hw, 1)[0]) > STILL_RATE_M_S:
            continue
        wa = (ta >= tb[i]) & (ta <= tb[i] + HOLD_S)
        if wa.sum() >= 5 and np.std(a[wa]) > rest_a:
            continue
        ground = float(np.median(hw))
        above = np.flatnonzero((tb < tb[i] + HOLD_S) & (h > ground + 3.0 * noise + 0.5)
                               & (tb > after))
        if above.size == 0:
            return FlightEvent(float(tb[i]), dtb, "altimeter")
        t_c = tb[above[-1]]
        fit = (tb >= t_c - 2.0) & (tb <= t_c) & (tb > after)
        if fit.sum() < 4:
            return FlightEvent(float(t_c), dtb, "altimeter")
        slope, icpt = np.polyfit(tb[fit] - t_c, h[fit], 1)
        t_down = t_c + (float(np.clip((ground - icpt) / slope, 0.0, 1.0)) if slope < 0 else 0.0)
        sigma = max(dtb, noise / abs(slope)) if slope < 0 else dtb
        near = (ta >= t_down - IMPACT_WINDOW_S) & (ta <= t_down + IMPACT_WINDOW_S)
        rest = (ta > t_down + IMPACT_WINDOW_S) & (ta <= t_down + HOLD_S)
        if near.sum() >= 3 and rest.sum() >= 3:
            jolt = np.abs(a[near] - float(np.median(a[rest])))
            if jolt.max() > SPIKE_MIN_G * G0:
                return FlightEvent(float(ta[near][np.argmax(jolt)]), _interval(ta),
                                   "accelerometer (impact)")
        return FlightEvent(float(t_down), float(sigma), "altimeter")
    return None
