"""Samples of a flight log that no flight produces: a damaged end, and the pressure swing
of an ejection charge in a recorder's filtered altitude.

**A damaged end.**  A recorder that loses power, resets or writes its buffer out badly
leaves samples at the log's end that are no descent's: on one public log the altitude
falls 216 m in half a second from a descent at 6 m/s.  A descending body is slowed by
its drag, never pulled down faster than free fall: from its rate r (m/s, negative
down) over the seconds before, the next sample's rate can lie at most g dt below r.  In
the log's last `TAIL_S` after its highest reading, the first sample whose rate from the
one before falls below that by more than `TAIL_SIGMAS` rate-noise sigmas, or whose rate
either way exceeds what no canopy descends at (`plausibility.MAX_DESCENT_M_S`) by as much
(a 1 kHz log's 0.2 m of noise reads 280 m/s from one sample to the next), starts
the damage; it ends at the first later sample back within reach of the flight (the last
good height, moved at most by the rate before and free fall, give or take
`TAIL_SIGMAS` height-noise sigmas): an impact's pressure pulse before the ground is one
sample, a reset or garbage runs to the end.  An impact itself only stops the fall and
is never cut.

**A body turned over.**  An axial accelerometer under a canopy reads the drag's specific
force along the body's axis, f cos(theta), theta the axis's angle to the riser: never
below zero while the body hangs below its canopy.  A vehicle that tumbles (on one log it
turns over for 5 s, its axis reading -15 m/s^2 where the drag gives +10) reads it
reversed, which no drag model makes: a fit would bend the air's motion to explain it.
`turned_over` finds such samples; the import does not yet leave them out (on one
Altus log the fit without them no longer converged).  Where the axial specific force's
running median over `TURNED_MEDIAN_S` is below zero by
more than `TURNED_SIGMAS` of its own sigma (the scatter about it, 1.4826 MAD, times
1.2533 / sqrt(n) for a median of n samples) and `TURNED_FLOOR_M_S2` (an accelerometer's
offset: a body falling free near apogee reads zero, not below), the body has turned over;
those samples and `TURNED_MARGIN_S` about them are left out.

**A charge's swing.**  A recorder's filter spreads an ejection charge's one-sample
pressure pulse over a second or more (on one filtered export the altitude dives 740 m
and climbs back in 1.3 s).  About each deployment, the samples off the altitude's
running median over `SWING_MEDIAN_S` by more than `SWING_SIGMAS` robust sigmas and
a charge's least pulse (`flight_events.PULSE_MIN_M`: an opening's kink in the altitude
stands a few metres off such a median, a charge's pulse tens to hundreds) within
`SWING_REACH_S` form its swing, left out like the charge's own window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cpas_ocp.io.flight_events import PULSE_MIN_M, second_difference_sigma
from cpas_ocp.io.plausibility import MAX_DESCENT_M_S
from cpas_ocp.physics.units import G0

TAIL_S = 5.0  # a damaged end is looked for in the log's last this long (s)


TAIL_SIGMAS = 6.0  # a rate (or height) this many noise sigmas beyond reach is not flight


RATE_BEFORE_S = 2.0  # the rate before a sample is the slope over this long (s)


SWING_MEDIAN_S = 3.0  # a charge's swing stands off the running median over this long (s) ...


SWING_SIGMAS = 8.0  # ... by this many robust sigmas of the scatter about it ...


SWING_REACH_S = 3.0  # ... within this long of the deployment (s)


TURNED_MEDIAN_S = 0.5  # a body turned over: the axial force's median over this long < 0 (s)


TURNED_SIGMAS = 5.0  # ... by this many sigmas of that median ...


TURNED_FLOOR_M_S2 = 1.0  # ... and this much at least (m/s^2) ...


TURNED_MARGIN_S = 0.5  # ... and the samples this long about it are left out too (s)


@dataclass(frozen=True)
class DamagedEnd:
    """Samples at a log's end that no descent produces: their positions in the altimeter's
    series, the time (s) the damage starts, and whether it runs to the log's end."""

    rows: np.ndarray
    t_from: float
    to_end: bool

    def note(self, t_last: float) -> str:
        """One sentence for the import's notes."""
        if self.to_end:
            return (f"the log's last {self.rows.size} altimeter sample(s), from "
                    f"{self.t_from:.2f} to {t_last:.2f} s, left out: no descent falls that "
                    "way (a reset, an impact or garbage at the end of the log); the log is "
                    f"taken to end at {self.t_from:.2f} s")
        return (f"{self.rows.size} altimeter sample(s) from {self.t_from:.2f} s near the "
                "log's end left out: no descent falls that way (an impact's pressure pulse?)")


def damaged_end(t: np.ndarray, h: np.ndarray) -> DamagedEnd | None:
    """The damaged end (see the module docstring) of the altitude `h` (m) at times `t` (s,
    increasing), or None where the log ends in flight or on the ground."""
    if t.size < 10:
        return None
    noise = max(second_difference_sigma(h), 0.05)
    k_top = int(np.argmax(h))
    first = max(k_top + 1, int(np.searchsorted(t, t[-1] - TAIL_S)), 2)
    rows = np.arange(first, t.size)
    count, rates = rates_before(t, h, rows - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dt = t[rows] - t[rows - 1]
        step = (h[rows] - h[rows - 1]) / dt
        step_noise = TAIL_SIGMAS * np.sqrt(2.0) * noise / dt
        damaged = (dt > 0.0) & (count >= 3) & (
            (step < rates - (G0 * dt + step_noise))
            | (np.abs(step) > MAX_DESCENT_M_S + step_noise))
    for i, rate in zip(rows[damaged], rates[damaged], strict=True):
        # Back within reach of the flight from the last good sample: the damage ends there.
        later = np.arange(i, t.size)
        lag = t[later] - t[i - 1]
        low = h[i - 1] + np.minimum(rate, 0.0) * lag - 0.5 * G0 * lag**2
        high = h[i - 1] + np.maximum(rate, 0.0) * lag
        back = np.flatnonzero((h[later] >= low - TAIL_SIGMAS * noise)
                              & (h[later] <= high + TAIL_SIGMAS * noise))
        end = int(later[back[0]]) if back.size else t.size
        return DamagedEnd(np.arange(i, end), float(t[i]), end == t.size)
    return None


def rates_before(t: np.ndarray, h: np.ndarray, ends: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares rate (m/s) of `h` (m) against `t` (s, increasing) over the
    RATE_BEFORE_S up to and including each sample of `ends` (indices), and how many
    samples that span holds: running sums over the span of every window, with times and
    heights taken from its start (the sums stay small whatever the log's clock and datum
    read)."""
    if not ends.size:
        return np.zeros(0, dtype=int), np.zeros(0)
    lo = np.searchsorted(t, t[ends] - RATE_BEFORE_S, side="left")
    start = int(lo.min())
    x = t[start:int(ends.max()) + 1] - t[start]
    y = h[start:int(ends.max()) + 1] - h[start]

    def running(v: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(v)])

    sx, sy, sxx, sxy = running(x), running(y), running(x * x), running(x * y)
    a, b = lo - start, ends - start + 1
    n = (b - a).astype(float)
    mx, my = (sx[b] - sx[a]) / np.maximum(n, 1.0), (sy[b] - sy[a]) / np.maximum(n, 1.0)
    cxx = sxx[b] - sxx[a] - n * mx * mx
    cxy = sxy[b] - sxy[a] - n * mx * my
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = np.where(cxx > 0.0, cxy / cxx, np.nan)
    return b - a, rate


def charge_swing(t: np.ndarray, h: np.ndarray, t_charge: float) -> tuple[float, float] | None:
    """The span (s) of the pressure swing about a charge at `t_charge` (s) in the altitude
    `h` (m) at times `t` (s): the first and last samples within `SWING_REACH_S` of it off
    the running median (see the module docstring); None where none is."""
    near = np.abs(t - t_charge) <= SWING_REACH_S
    if near.sum() < 10:
        return None
    interval = float(np.median(np.diff(t)))
    n = max(3, round(SWING_MEDIAN_S / interval)) if interval > 0 else 3
    trend = pd.Series(h).rolling(n, center=True, min_periods=1).median().to_numpy()
    off = h - trend
    scatter = 1.4826 * float(np.median(np.abs(off - np.median(off))))
    swing = near & (np.abs(off) > max(SWING_SIGMAS * scatter, PULSE_MIN_M))
    if not swing.any():
        return None
    return float(t[swing].min()), float(t[swing].max())


def turned_over(t: np.ndarray, specific_force: np.ndarray) -> np.ndarray:
    """Which samples of an axial accelerometer, at times `t` (s) reading the axial
    `specific_force` (m/s^2, gravity not subtracted: +g at rest, nose up), the body has
    turned over in (see the module docstring): where the running median over
    `TURNED_MEDIAN_S` is significantly below zero, and within `TURNED_MARGIN_S` of such
    samples."""
    if t.size < 3:
        return np.zeros(t.size, dtype=bool)
    interval = float(np.median(np.diff(t)))
    n = max(3, round(TURNED_MEDIAN_S / interval)) if interval > 0 else 3
    median = pd.Series(specific_force).rolling(n, center=True, min_periods=1).median() \
        .to_numpy()
    off = specific_force - median
    scatter = 1.4826 * float(np.median(np.abs(off - np.median(off))))
    limit = max(TURNED_SIGMAS * 1.2533 * scatter / np.sqrt(n), TURNED_FLOOR_M_S2)
    over = t[median < -limit]
    if over.size == 0:
        return np.zeros(t.size, dtype=bool)
    k = np.searchsorted(over, t)
    before = np.abs(t - over[np.clip(k - 1, 0, over.size - 1)])
    after = np.abs(over[np.clip(k, 0, over.size - 1)] - t)
    return np.minimum(before, after) <= TURNED_MARGIN_S


def flagged_stretches(t: np.ndarray, flagged: np.ndarray) -> list[tuple[float, float]]:
    """The (first, last) times (s) of each run of consecutive `flagged` samples at times
    `t`."""
    edges = np.diff(np.concatenate([[0], flagged.astype(np.int8), [0]]))
    return [(float(t[a]), float(t[b - 1]))
            for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1),
                            strict=True)]
