"""Two recorders on one flight, on one time base: the offset between their clocks.

Each Altus Metrum recorder counts time from its own detection of the boost,
so two recorders on the same rocket (a primary and a backup altimeter)
disagree by however far apart they decided that the motor had lit.  The
offset is measured where both accelerometers see one sharp event: the
motor's thrust curve (ignition to burnout) or the drogue's opening.  The
axial accelerations of both, interpolated on a 1 ms grid over the window,
are aligned by the shift that minimises their mean-removed squared
difference (a least-squares cross-correlation); the result is good to
about the samples' spacing.

On the Prometheus flight the TeleMetrum's clock reads 0.070 s more than the
TeleMega's for the same instant from the boost (-0.3 to 6 s, 100 Hz), 0.071 s
from the drogue's opening (25 to 35 s, 10 Hz); the GPS seconds, which each
receiver reports with its own latency, change 0.14 s apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cpas_ocp.io.flight_record import FlightRecord

GRID_S = 0.001  # the alignment's grid (s)
BOOST_WINDOW_S = (-0.3, 6.0)  # the motor's burn in a log's own time (s)


def _acceleration(log: FlightRecord, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """The log's own axial acceleration samples (m/s^2) within [t0, t1] of its time (s)."""
    d = log.samples
    d = d[(d.time >= t0) & (d.time <= t1) & d.acceleration.notna()]
    return d.time.to_numpy(float), d.acceleration.to_numpy(float)


def clock_offset(a: FlightRecord, b: FlightRecord, window: tuple[float, float] = BOOST_WINDOW_S,
                 search_s: float = 0.5) -> float:
    """The time (s) to add to `a`'s log time to get `b`'s for the same instant, from the
    axial accelerations both recorded over `window` of `a`'s time, shifts searched
    within +-`search_s`.  Raises ValueError where either log has fewer than ten
    accelerometer samples in the window."""
    ta, ya = _acceleration(a, *window)
    tb, yb = _acceleration(b, window[0] - search_s, window[1] + search_s)
    for log, t in ((a, ta), (b, tb)):
        if t.size < 10:
            raise ValueError(f"{log.path}: fewer than ten accelerometer samples within "
                             f"{window[0]:g}-{window[1]:g} s to align the clocks by")
    grid = np.arange(window[0], window[1], GRID_S)
    reference = np.interp(grid, ta, ya)
    shifts = np.arange(-search_s, search_s + GRID_S / 2, GRID_S)
    cost = np.empty(shifts.size)
    for i, shift in enumerate(shifts):
        difference = reference - np.interp(grid + shift, tb, yb)
        cost[i] = np.var(difference)
    return float(shifts[int(np.argmin(cost))])


@dataclass(frozen=True)
class RecorderEstimates:
    """One recorder's reconstruction: its log, and the estimate and sigma (SI) of each
    drag area and start time."""

    log: FlightRecord
    estimates: dict[str, tuple[float, float]]
