"""Flight events found in a rocket's barometer and axial accelerometer.

Where a flight computer logged no flight states, `detect_events` finds them
in the `flight_record.FlightRecord`'s samples, each with its time (s) and
timing sigma (s):

* ``boost``: the first of `BOOST_RUN` accelerometer samples reading more than
  `BOOST_G` (the reading, 1 g subtracted, is 0 at rest on the pad: the
  motor lit); sigma one sample;
* ``coast`` (burnout): the first sample after that whose specific force is
  below zero (axial reading below -1 g: the drag exceeds what thrust is
  left); sigma one sample;
* ``apogee``: the highest point of the altimeter's running median over
  `SMOOTH_S`; sigma half the time that median stays within two noise sigmas
  (`second_difference_sigma`, at least 5 cm) of the top, at least one sample;
* ``drogue``, ``main``: the ejection charges.  A charge jolts the
  accelerometer (and the shock cord's snatch follows) and its gas puffs the
  static port, which reads a pressure pulse (on the Prometheus logs 155 and
  603 m of altitude in one sample, a 27 g jolt).  Samples further than
  `SPIKE_SIGMAS` robust sigmas (and at least `SPIKE_MIN_G`, or `PULSE_MIN_M`
  for the altimeter) off the running median over `SMOOTH_S` are spikes (a
  rocket swinging under its drogue reads up to 4.6 g and 18 m off it there);
  spikes closer than `CLUSTER_GAP_S` are one charge (its opening's snatch
  included).  The pressure pulse is the charge's gas: where the altimeter
  shows one, the charge is its first sample, sigma that sample's interval
  (or, where the accelerometer's first spike is within `SAME_S`, both saw
  the charge: the earlier, sigma their disagreement or sample interval).
  The accelerometer alone may show only the opening's snatch, up to
  `SNATCH_LAG_S` after the charge: its first spike, with that lag as sigma.  The drogue's is the
  first charge from one second plus apogee's sigma before apogee to
  `DROGUE_WINDOW_S` after it; with none there the drogue is taken to open at
  apogee (its time and sigma, and a note).  The main's is the next charge;
  more are reported in a note;
  A jolt within `GROUND_BAND_M` of the descent's lowest reading is the impact on the
  ground, never a charge;
* ``landed`` (touchdown, `touchdown`): from when the altitude stops falling.

Each sensor is read over its own span: a log may be several files, an altimeter's that
ends at apogee or just after the drogue's charge beside a GNSS file (1-10 Hz fixes with
an altitude) that goes on to the ground.  Where the barometer stops in the air and the
GNSS altitude reads on past its end (`gnss_reads_on`), touchdown is the GNSS's, the
descent's lowest reading (the ground of the impact rule) is the GNSS's, and the
accelerometer's jolts are looked for over its own samples up to the GNSS's touchdown or
end, not the barometer's end.  No charge is ever looked for in the GNSS altitude: a fix's
noise and jumps (its last fixes as the receiver loses its lock on the ground) are no
pressure pulse.

What cannot be found (no accelerometer, no boost in the log) is left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cpas_ocp.physics.units import G0

BOOST_G = 3.0  # a boost reads more than this many g (1 g subtracted) ...
BOOST_RUN = 3  # ... for this many samples in a row
SMOOTH_S = 1.0  # running-median window of the spike and apogee searches (s)
SPIKE_SIGMAS = 8.0  # a spike stands this many robust sigmas off the running median ...
SPIKE_MIN_G = 6.0  # ... and at least this far (g) for the accelerometer
PULSE_MIN_M = 30.0  # ... or this far (m of pressure altitude) for the altimeter
SAME_S = 0.3  # the two sensors' first spikes closer than this saw the same charge (s)
SNATCH_LAG_S = 1.0  # an opening's snatch comes up to this long after its charge (s)
DROGUE_WINDOW_S = 5.0  # the drogue's charge comes within this long after apogee (s)
CLUSTER_GAP_S = 3.0  # spikes closer than this are one ejection (charge, then snatch)
AFTER_BURNOUT_S = 1.0  # charges are looked for from this long after burnout (s)
HOLD_S = 3.0  # landed: still for this long (s) ...
MIN_HOLD_S = 1.0  # ... or, where the log ends sooner, for what is left of it, at least this
MIN_STILL_SAMPLES = 3  # ... and this many samples (a 1 Hz log's last 2 s)
NOISE_LAG_S = 0.5  # a filtered altitude's noise is read at lags up to this (s) ...
MIN_NOISE_DIFFS = 20  # ... where the stretch spans this many lags at least
STILL_RATE_M_S = 0.5  # ... the altitude's slope within this (m/s)
STILL_BAND_SIGMAS = 6.0  # ... its range within this many noise sigmas (+ STILL_BAND_M)
STILL_BAND_M = 1.0
STILL_TAIL_PCT = 1.0  # ... less its extreme percent either way (a range grows with n)
REST_ACCEL_M_S2 = 1.0  # ... and the accelerometer's scatter within this (or 3 pad sigmas)
IMPACT_WINDOW_S = 0.5  # the landing's impact is looked for this close to the baro's touchdown
GROUND_BAND_M = 20.0  # a jolt this close above the descent's lowest reading is the impact
MIN_GNSS_FIXES = 5  # least GNSS fixes past the barometer's end that read on the descent
HOLD_SAMPLES = 5  # a still stretch holds at least this many samples (a 1 Hz GNSS: 5 s)
STILL_SLOPE_SIGMAS = 3.0  # a still stretch's slope within this many of its noise's sigmas


@dataclass(frozen=True)
class FlightEvent:
    """A flight event: time (s), timing sigma (s), and what found it."""

    time: float
    sigma: float
    source: str


def second_difference_sigma(values: np.ndarray, lag: int = 1) -> float:
    """White-noise sigma of a smooth signal's samples: 1.4826 MAD of the second
    differences over sqrt(6) (the second difference of white noise has variance 6 s^2),
    taken `lag` samples apart (x[k + 2 lag] - 2 x[k + lag] + x[k])."""
    if values.size <= 2 * lag:
        return float("nan")
    d2 = values[2 * lag:] - 2.0 * values[lag:-lag] + values[:-2 * lag]
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def level_noise(t: np.ndarray, h: np.ndarray) -> float:
    """White-noise sigma (m) of an altitude `h` at times `t` (s) as its level scatters: the
    largest `second_difference_sigma` at lags of 1, 2, 4, ... samples up to NOISE_LAG_S,
    each where `h` holds MIN_NOISE_DIFFS of its lags' spans at least (NaN where none does).

    A recorder's filter correlates its output's noise over its time constant, and a
    quantised reading repeats itself: the differences of neighbouring samples then read a
    fraction of the scatter (the Lince 2023 CATS filtered export, at rest on the ground:
    0.05 m one sample apart, 0.3 m 0.1 s apart and beyond, its scatter 0.33 m).  White
    noise reads the same at every lag."""
    lags = [1]
    while 2 * lags[-1] * sample_interval(t) <= NOISE_LAG_S:
        lags.append(2 * lags[-1])
    sigmas = [second_difference_sigma(h, lag) for lag in lags
              if h.size - 2 * lag >= MIN_NOISE_DIFFS * lag]
    return max(sigmas) if sigmas else float("nan")


def sample_interval(t: np.ndarray) -> float:
    """Median sample interval (s)."""
    return float(np.median(np.diff(t))) if t.size > 1 else float("nan")


def _step_at(t: np.ndarray, t0: float) -> float:
    """The sample interval (s) that ends at the sample at `t0`: the timing sigma of an event
    first seen in that sample (loggers slow down in the descent)."""
    k = int(np.searchsorted(t, t0))
    return float(t[k] - t[k - 1]) if 0 < k < t.size else sample_interval(t)


def _running_median(t: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """Centred running median of `x` over about `window_s` (s) of samples (an odd count, at
    least 3, from the median interval of `t`); the ends over the samples there are."""
    n = max(3, round(window_s / sample_interval(t)) // 2 * 2 + 1)
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


def gnss_reads_on(t_baro: np.ndarray, gnss: pd.DataFrame | None) -> bool:
    """Whether the GNSS altitude (`gnss`: ``time`` s, ``gps_altitude`` m) reads on more than
    `HOLD_S` past the barometer's last sample (`t_baro`, s), with at least
    `MIN_GNSS_FIXES` fixes after it: a descent the barometer's file does not cover."""
    if gnss is None or gnss.empty or t_baro.size == 0:
        return False
    after = gnss["time"].to_numpy(float) > t_baro[-1]
    return bool(after.sum() >= MIN_GNSS_FIXES
                and gnss["time"].to_numpy(float)[after][-1] > t_baro[-1] + HOLD_S)


def detect_events(samples: pd.DataFrame, gnss: pd.DataFrame | None = None
                  ) -> tuple[dict[str, FlightEvent], list[str]]:
    """The events of the module docstring found in a record's `samples` (time (s), altitude
    (m), acceleration (m/s^2, 1 g subtracted)), and notes on what could not be told;
    `gnss` (``time`` s, ``gps_altitude`` m), where the log has GNSS altitudes, gives
    touchdown and the ground's level where the barometer stops in the air and the GNSS
    reads on (`gnss_reads_on`)."""
    accel = samples[["time", "acceleration"]].dropna()
    baro = samples[["time", "altitude"]].dropna()
    ta, a = accel["time"].to_numpy(float), accel["acceleration"].to_numpy(float)
    tb, h = baro["time"].to_numpy(float), baro["altitude"].to_numpy(float)
    events: dict[str, FlightEvent] = {}
    notes: list[str] = []
    if ta.size > 20:
        high = pd.Series(a > BOOST_G * G0).rolling(BOOST_RUN).sum().to_numpy()
        runs = np.flatnonzero(high >= BOOST_RUN)
        if runs.size:
            k = runs[0] - BOOST_RUN + 1
            events["boost"] = FlightEvent(float(ta[k]), _step_at(ta, ta[k]), "accelerometer")
            after = np.flatnonzero((ta > ta[runs[0]]) & (a + G0 < 0.0))
            if after.size:
                t_out = float(ta[after[0]])
                events["coast"] = FlightEvent(t_out, _step_at(ta, t_out), "accelerometer")
    if "boost" not in events:
        notes.append("no boost found in the accelerometer: boost and burnout not detected")
    if tb.size < 20:
        notes.append("too few altimeter samples to find apogee and touchdown")
        return events, notes
    start = events["coast"].time if "coast" in events else tb[0]
    smooth = _running_median(tb, h, SMOOTH_S)
    up = tb >= start
    if not up.any():  # the altimeter stopped before the accelerometer's burnout
        notes.append("no altimeter samples after burnout: apogee and touchdown not detected")
        return events, notes
    k_top = int(np.flatnonzero(up)[np.argmax(smooth[up])])
    noise = max(second_difference_sigma(h), 0.05)
    near_top = tb[up][np.abs(smooth[up] - smooth[k_top]) <= 2.0 * noise]
    events["apogee"] = FlightEvent(float(tb[k_top]),
                                   max(_step_at(tb, tb[k_top]),
                                       0.5 * float(near_top.max() - near_top.min())),
                                   "altimeter")
    down = touchdown(tb, h, ta, a, float(tb[k_top]))
    # The channel that reads the descent to its end: the barometer, or the GNSS where the
    # barometer's file stops in the air and the GNSS's reads on.
    t_low, h_low = tb, smooth
    if down is None and gnss_reads_on(tb, gnss):
        assert gnss is not None
        tg, hg = gnss["time"].to_numpy(float), gnss["gps_altitude"].to_numpy(float)
        t_low, h_low = tg, _running_median(tg, hg, SMOOTH_S)
        down = touchdown(tg, hg, ta, a, float(tb[k_top]))
        if down is not None and down.source == "altimeter":
            down = FlightEvent(down.time, down.sigma, "GNSS altitude")
    # Each sensor over its own span: the altimeter's pulses up to its end, the
    # accelerometer's jolts up to the end of the channel that reads their height.
    t_stop_b = down.time - HOLD_S if down is not None else float(tb[-1])
    t_stop_a = down.time - HOLD_S if down is not None else float(t_low[-1])
    lo = start + (AFTER_BURNOUT_S if "coast" in events else 0.0)
    in_a, in_b = (ta >= lo) & (ta < t_stop_a), (tb >= lo) & (tb < t_stop_b)
    jolts = _spikes(ta, a, SPIKE_MIN_G * G0, in_a)
    pulses = _spikes(tb, h, PULSE_MIN_M, in_b)
    charges = _ejections(jolts, pulses, ta, tb)
    top = events["apogee"]
    # No canopy is deployed at the ground: a jolt within GROUND_BAND_M of the descent's
    # lowest reading is its impact (a log that ends at the impact finds no touchdown).
    after_top = t_low > top.time
    if after_top.any():
        ground = float(h_low[after_top].min())
        impacts = [c for c in charges if c.time > top.time
                   and float(np.interp(c.time, t_low, h_low)) <= ground + GROUND_BAND_M]
        if impacts:
            notes.append(f"a jolt at {impacts[0].time:.2f} s, at the descent's lowest "
                         "reading: the impact on the ground, not an ejection charge")
            charges = [c for c in charges if c not in impacts]
    near = [c for c in charges
            if top.time - top.sigma - 1.0 <= c.time <= top.time + DROGUE_WINDOW_S]
    if near:
        events["drogue"] = near[0]
    else:
        events["drogue"] = FlightEvent(top.time, top.sigma, "apogee (no charge seen)")
        notes.append("no ejection charge seen near apogee: the drogue is taken to open at "
                     "apogee")
    later = [c for c in charges if c.time > events["drogue"].time + CLUSTER_GAP_S]
    if later:
        events["main"] = later[0]
    else:
        notes.append("no later ejection charge found in the accelerometer or the altimeter: "
                     "no main")
    extra = [c for c in charges if c is not events["drogue"] and c not in later[:1]]
    if extra:
        notes.append(f"{len(extra)} more ejection-like disturbance(s), at "
                     f"{', '.join(f'{e.time:.2f}' for e in extra)} s: not used")
    if down is not None:
        events["landed"] = down
    return events, notes


def _ejections(jolts: np.ndarray, pulses: np.ndarray, ta: np.ndarray, tb: np.ndarray
               ) -> list[FlightEvent]:
    """One event per cluster of spikes (see the module docstring); `ta`, `tb` the
    accelerometer's and the altimeter's sample times."""
    marks = sorted([(t, "accelerometer") for t in jolts] + [(t, "altimeter") for t in pulses])
    clusters: list[list[tuple[float, str]]] = []
    for mark in marks:
        if clusters and mark[0] - clusters[-1][-1][0] <= CLUSTER_GAP_S:
            clusters[-1].append(mark)
        else:
            clusters.append([mark])
    out = []
    for cluster in clusters:
        first: dict[str, float] = {}
        for t, source in cluster:
            first.setdefault(source, t)
        t0, source = cluster[0]
        step = {"accelerometer": _step_at(ta, t0) if ta.size else np.nan,
                "altimeter": _step_at(tb, t0) if tb.size else np.nan}
        if "altimeter" not in first:
            # The accelerometer alone: the spike may be the opening's snatch, not the charge.
            sigma = max(step["accelerometer"], SNATCH_LAG_S)
        elif len(first) == 2 and abs(first["accelerometer"] - first["altimeter"]) <= SAME_S:
            # Both sensors saw the charge.
            sigma = max(step["accelerometer"], step["altimeter"],
                        abs(first["accelerometer"] - first["altimeter"]))
            source = "accelerometer and altimeter"
        else:
            sigma = step["altimeter"]
            t0, source = first["altimeter"], "altimeter"
        out.append(FlightEvent(float(t0), float(sigma), source))
    return out


def touchdown(tb: np.ndarray, h: np.ndarray, ta: np.ndarray, a: np.ndarray,
              after: float) -> FlightEvent | None:
    """Touchdown after `after` (s), or None where the log ends before the vehicle is down.

    The ground: the first stretch after `after` where the altitude stays still.  Still:
    its slope within STILL_RATE_M_S (or STILL_SLOPE_SIGMAS of the noise's slope sigma over
    the stretch, where that is larger: a GNSS's metres of noise), its range (but its
    STILL_TAIL_PCT extreme percent either way: the range of n samples of noise grows with
    n, 7.4 sigmas for a 1 kHz log's 3000) within STILL_BAND_SIGMAS noise sigmas (+
    STILL_BAND_M), over HOLD_S and HOLD_SAMPLES samples;
    where the log ends sooner, over what is left of it, at least MIN_HOLD_S and
    MIN_STILL_SAMPLES samples, and then the slope's bound (its value and
    STILL_SLOPE_SIGMAS of its sigma) below the descent's rate: a short stretch must tell
    the rest from the descent before it.  The accelerometer's scatter there is within
    REST_ACCEL_M_S2 (or three times the pad's).  The noise is the still stretch's own
    (`level_noise`: a filter's correlated scatter counted), at least the whole channel's
    `second_difference_sigma` (a quantised reading at rest repeats itself).

    The ground's level is the still stretch's median altitude, and the descent ends where
    it first comes down to that level (within three noise sigmas and 0.5 m) after it was
    last GROUND_BAND_M (or two such margins) above it: a descent does not climb back metres
    from the ground, so what a recorder's filter does after its impact (an overshoot below
    the ground and a rebound of metres above it) is not the descent's.  The touchdown time
    is where the line through the last 2 s (four samples at least) of the descent before
    that meets the ground level; where the accelerometer shows the impact within
    IMPACT_WINDOW_S of it, the impact's sample.  Sigma: one sample interval of the sensor
    that timed it, or the noise over the descent rate.  `tb`, `h`: the altitude channel's
    times (s) and heights (m): the barometer's, or a GNSS's at 1-10 Hz."""
    descent = tb > after
    floor = max(second_difference_sigma(h), 0.05)
    rest_a = (max(REST_ACCEL_M_S2, 3.0 * float(np.std(a[: max(10, ta.size // 20)])))
              if ta.size > 20 else np.inf)
    dtb = sample_interval(tb)
    hold_s = max(HOLD_S, HOLD_SAMPLES * dtb)
    min_hold_s = max(MIN_HOLD_S, (MIN_STILL_SAMPLES - 1) * dtb)
    step = max(1, round(0.1 / dtb))
    for i in np.flatnonzero(descent)[::step]:
        # A log that ends soon after landing holds still for what is left, MIN_HOLD_S at least.
        hold = min(hold_s, float(tb[-1] - tb[i]))
        if hold < min_hold_s - 1e-9:
            return None
        short = hold < hold_s
        w = slice(int(np.searchsorted(tb, tb[i], side="left")),
                  int(np.searchsorted(tb, tb[i] + hold, side="right")))  # tb increases
        if w.stop - w.start < (MIN_STILL_SAMPLES if short else HOLD_SAMPLES):
            continue
        hw, tw = h[w], tb[w] - tb[i]
        # The noise at rest, a filter's correlated scatter counted.
        noise = max(np.nan_to_num(level_noise(tw, hw)), floor)
        band = STILL_BAND_SIGMAS * noise + STILL_BAND_M
        margin = 3.0 * noise + 0.5  # a sample this close above the ground's level reads it
        slope_sigma = noise / float(np.sqrt(np.sum((tw - tw.mean()) ** 2)))
        still_rate = max(STILL_RATE_M_S, STILL_SLOPE_SIGMAS * slope_sigma)
        still_slope = float(np.polyfit(tw, hw, 1)[0])
        spread = np.subtract(*np.percentile(hw, [100.0 - STILL_TAIL_PCT, STILL_TAIL_PCT]))
        if spread > band or abs(still_slope) > still_rate:
            continue
        wa = (ta >= tb[i]) & (ta <= tb[i] + hold)
        if wa.sum() >= 5 and np.std(a[wa]) > rest_a:
            continue
        ground = float(np.median(hw))
        # The descent's end: its first reading at the ground's level since it was last
        # well above it.
        k_first = int(np.flatnonzero(descent)[0])
        high = np.flatnonzero(descent & (tb < tb[i])
                              & (h > ground + max(GROUND_BAND_M, 2.0 * margin)))
        start = int(high[-1]) if high.size else k_first
        reached = start + int(np.argmax(h[start:] <= ground + margin))
        if reached <= k_first:
            return FlightEvent(float(tb[i]), _step_at(tb, tb[i]), "altimeter")
        t_c = float(tb[reached - 1])
        fit = (tb >= t_c - max(2.0, 3.0 * dtb)) & (tb <= t_c) & descent
        if fit.sum() < 4:
            if short:
                continue  # too few samples of the descent to tell the rest from it
            return FlightEvent(t_c, _step_at(tb, t_c), "altimeter")
        slope, icpt = np.polyfit(tb[fit] - t_c, h[fit], 1)
        if short and abs(still_slope) + STILL_SLOPE_SIGMAS * slope_sigma >= abs(slope):
            continue
        # The ground lies within the margin below the last sample above it, at most twice
        # the time the descent takes across that margin (a second at least).
        reach = max(1.0, 2.0 * margin / abs(slope)) if slope < 0 else 0.0
        t_down = t_c + (float(np.clip((ground - icpt) / slope, 0.0, reach)) if slope < 0 else 0.0)
        step_c = _step_at(tb, t_c)
        sigma = max(step_c, noise / abs(slope)) if slope < 0 else step_c
        near = (ta >= t_down - IMPACT_WINDOW_S) & (ta <= t_down + IMPACT_WINDOW_S)
        rest = (ta > t_down + IMPACT_WINDOW_S) & (ta <= t_down + HOLD_S)
        if near.sum() >= 3 and rest.sum() >= 3:
            jolt = np.abs(a[near] - float(np.median(a[rest])))
            if jolt.max() > SPIKE_MIN_G * G0:
                t_hit = float(ta[near][np.argmax(jolt)])
                return FlightEvent(t_hit, _step_at(ta, t_hit), "accelerometer (impact)")
        return FlightEvent(float(t_down), float(sigma), "altimeter")
    return None
