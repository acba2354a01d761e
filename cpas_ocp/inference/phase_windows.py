"""The physical phases of a reconstructed test, as time windows per canopy.

A canopy goes through three kinds of phase, each with its own physics and
so its own ways for a model to fail:

* **deployment** (from the canopy's first observed event, mortar fire, line
  stretch or bag strip, else from the start of the data, to the inflation
  start t_i of its first stage): the pack and lines leave the vehicle; the
  load is the deployment (snatch) load and the canopy carries no drag area;
* **inflation** of a stage (from its fitted start t_i[P,S]): the drag area
  rises per Eq. 5 and, for infinite-mass canopies, overshoots to Ck CdS_i and
  settles per Eq. 6; the loads peak, and added mass, riser elasticity and
  fill-shape errors show here;
* **steady** (the rest of the stage, until the next stage starts or the
  phase ends): the drag area holds CdS_i; what is left is drag level,
  sensor calibration and slow effects.

The inflation window ends where the canopy's reconstructed drag area
``cds[P]`` (m^2) has settled: after the last grid time at which it differs
from the stage's steady ``CdS[P,S]`` by more than SETTLED_FRACTION (2 %),
and never before the end of the rise ``rise_end[P,S]`` (the over-inflation
peak t_i + t_fp for infinite mass, the end of the fill t_i + t_f for finite
mass).  By Eq. 6 the overshoot Ck^(1 - u) - 1 (u the time since the peak
over t_k) is within 2 % at u = 1 - ln 1.02 / ln Ck: 0.95 t_k for Ck = 1.45,
0.77 t_k for Ck = 1.09, so the window keeps almost all of the settling,
and a finite-mass fill is cut where it is within 2 % of its steady value.
2 % is the load cells' relative noise in the built-in problems: beyond it
the canopy's load no longer tells inflation from steady flight.  It is
capped at the next stage's start (a disreef before settling leaves the stage
no steady window).

Windows are closed intervals [t0, t1] (s) inside the fit's grid, never
empty.  Canopies overlap one another in time; a sample of a sensor that
sees several canopies (GPS, IMU) belongs to one window by the rule of
`window_index`, so that windows partition every channel's samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cpas_ocp.physics.parameters import param_name

if TYPE_CHECKING:
    from cpas_ocp.estimation.estimator import Fit
    from cpas_ocp.physics.flight_test import FlightTest, Parachute

KINDS = ("deployment", "inflation", "steady")
# Events that start a canopy's deployment, whichever of them was observed first.
DEPLOYMENT_EVENTS = ("mortar_fire", "line_stretch", "bag_strip")
# Relative distance of cds[P] from CdS[P,S] below which a stage counts as settled.
SETTLED_FRACTION = 0.02
# When windows of several canopies hold a sample: inflation, then deployment, then steady
# flight, and among the same kind the one that began last (the most recent transient).
KIND_PRIORITY = {"inflation": 0, "deployment": 1, "steady": 2}
# Name under which a channel's samples outside every window are reported.
OUTSIDE = "outside windows"
# Shortest window kept (s); shorter ones are rounding debris of coinciding times.
MIN_WIDTH_S = 1e-9


@dataclass(frozen=True)
class PhaseWindow:
    """One phase of one canopy, e.g. ``inflation drogue1 stage2``, from t0 to t1 (s)."""

    name: str
    kind: str
    parachute: str
    stage: str | None
    t0: float
    t1: float

    def contains(self, t: np.ndarray) -> np.ndarray:
        """Whether each time (s) lies in the closed window."""
        t = np.asarray(t, dtype=float)
        return (t >= self.t0) & (t <= self.t1)


def phase_windows(fit: Fit) -> list[PhaseWindow]:
    """Deployment, inflation and steady windows of every canopy, from the fit's own
    parameters and drag areas; sorted by start time.

    A canopy without stages, or whose stages carry no start time (a model
    without the `canopy_inflation` effect), has no windows; a canopy open at the
    phase's start has one steady window, the whole phase.
    """
    q = fit.quantities()
    lo, hi = float(fit.t[0]), float(fit.t[-1])
    out: list[PhaseWindow] = []
    for chute in fit.test.parachutes:
        out += _canopy_windows(fit, chute, q, lo, hi)
    return sorted(out, key=lambda w: (w.t0, w.t1, w.name))


def _canopy_windows(fit: Fit, chute: Parachute, q: dict[str, np.ndarray], lo: float,
                    hi: float) -> list[PhaseWindow]:
    out: list[PhaseWindow] = []
    if chute.open_at_start:  # open and steady from the phase's start: one steady window
        for stage in chute.stages:
            _append(out, f"steady {chute.name} {stage}", "steady", chute.name, stage, lo, hi)
        return out
    starts = [(s, fit.parameters[param_name("t_start", chute.name, s)]) for s in chute.stages
              if param_name("t_start", chute.name, s) in fit.parameters]
    if not starts:
        return []
    starts.sort(key=lambda st: st[1])
    observed = [e.time for e in fit.test.events
                if e.parachute == chute.name and e.name in DEPLOYMENT_EVENTS]
    deploy = min(observed) if observed else lo
    _append(out, f"deployment {chute.name}", "deployment", chute.name, None,
            max(deploy, lo), min(starts[0][1], hi))
    cds = q.get(param_name("cds", chute.name))
    for k, (stage, t_start) in enumerate(starts):
        t0 = max(t_start, lo)
        cap = min(starts[k + 1][1], hi) if k + 1 < len(starts) else hi
        if cap - t0 <= MIN_WIDTH_S:
            continue
        steady = fit.parameters.get(param_name("CdS", chute.name, stage))
        rise_end = q.get(param_name("rise_end", chute.name, stage))
        peak = None if rise_end is None else float(np.interp(t0, fit.t, rise_end))
        end = min(settling_end(fit.t, cds, steady, t0, cap, peak), cap)
        label = f"{chute.name} {stage}"
        _append(out, f"inflation {label}", "inflation", chute.name, stage, t0, end)
        _append(out, f"steady {label}", "steady", chute.name, stage, end, cap)
    return out


def settling_end(t: np.ndarray, cds: np.ndarray | None, steady: float | None, t0: float,
                 cap: float, rise_end: float | None = None) -> float:
    """Time (s) at which a stage that starts at t0 has settled: the grid time after the last
    one before `cap` where the drag area `cds` (m^2, on grid `t`) is further than
    SETTLED_FRACTION from the steady value `steady` (m^2; None: the drag area just before
    `cap`), and no earlier than `rise_end` (s).  Without a drag area: `rise_end`, else
    `cap`."""
    floor = t0 if rise_end is None else max(t0, rise_end)
    if cds is None:
        return cap if rise_end is None else floor
    sel = np.flatnonzero((t >= t0) & (t < cap))
    if sel.size == 0:
        return cap
    ref = float(cds[sel[-1]]) if steady is None else float(steady)
    off = np.abs(cds[sel] - ref) > SETTLED_FRACTION * max(abs(ref), 1e-12)
    if not off.any():
        return floor
    last = int(sel[np.flatnonzero(off)[-1]])
    settled = float(t[last + 1]) if last + 1 < t.size else float(t[-1])
    return max(settled, floor)


def _append(out: list[PhaseWindow], name: str, kind: str, chute: str, stage: str | None,
            t0: float, t1: float) -> None:
    if t1 - t0 > MIN_WIDTH_S:
        out.append(PhaseWindow(name, kind, chute, stage, float(t0), float(t1)))


def windows_for_sensor(test: FlightTest, sensor: str,
                       windows: Sequence[PhaseWindow]) -> list[PhaseWindow]:
    """The windows that apply to a sensor: its own canopy's for a riser load cell, every
    canopy's for a sensor on the vehicle (GPS, IMU) or one the test does not list."""
    chute = next((s.parachute for s in test.sensors if s.name == sensor), None)
    own = [w for w in windows if w.parachute == chute]
    return own if chute is not None and own else list(windows)


def window_index(t: np.ndarray, windows: Sequence[PhaseWindow]) -> np.ndarray:
    """For each sample time (s), the index in `windows` of the one window it belongs to, or
    -1 outside every window.

    Where windows overlap (two canopies, or the shared boundary of two phases) the
    sample goes by KIND_PRIORITY: inflation, then deployment, then steady, and among
    windows of the same kind the one that began last.
    """
    t = np.asarray(t, dtype=float)
    index = np.full(t.size, -1, dtype=int)
    order = sorted(range(len(windows)),
                   key=lambda i: (KIND_PRIORITY.get(windows[i].kind, len(KIND_PRIORITY)),
                                  -windows[i].t0))
    for i in order:
        index[(index < 0) & windows[i].contains(t)] = i
    return index
