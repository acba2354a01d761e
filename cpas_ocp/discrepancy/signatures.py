"""Candidate signatures of missing physics, and how a residual correlates with them.

A model that lacks an effect leaves a residual shaped like the quantity that
effect follows.  Each signature here is a series along the fitted trajectory
on the shooting grid, with the missing physics it points to:

* ``dynamic_pressure`` (Pa): a force error proportional to q: a wrong drag
  area or drag scale in the window, the wake's pressure recovery (PRF), a
  density error of the atmosphere;
* ``airspeed`` (m/s): a speed-dependent error: a wind error, a velocity scale
  error of the GPS, Reynolds- or Mach-dependent drag;
* ``load_factor`` (g): the vehicle's acceleration: an accelerometer scale
  error, a GPS velocity lag (a lag tau leaves -tau times the acceleration in
  the velocity residual), the inertial load of canopy and air mass in a riser;
* ``d(load_factor)/dt`` (g/s): an IMU lag or filter (a lag leaves -tau dh/dt),
  a compliance (riser elasticity) that delays the load;
* ``altitude`` (m): an error that varies with height: a wind that changes
  with altitude (shear), a wrong atmosphere (density, temperature);
* ``tension[P]`` (N), where the model has a riser tension: a load-cell gain
  that varies with the load (a nonlinear cell, a loss that grows with tension);
* ``cds[P]`` (m^2): the canopy's drag area: an error in its level (steady
  CdS, drag or load-cell scale in the window);
* ``dCdS/dt[P]`` (m^2/s): the drag area's growth rate: added (enclosed and
  apparent) air mass, whose force d(m_A)/dt v follows it; fairlead friction
  on a load cell that follows the load's rate; a wrong fill shape (n_p,
  expopen);
* ``dT/dt[P]`` (N/s), where the model has a riser tension: a load-cell lag or
  rate-dependent friction (a lag leaves -tau dT/dt);
* ``stretch[P]`` (m), where the model has elastic risers: riser elasticity
  beyond the linear spring-damper (stiffening, hysteresis) or a wrong riser
  frequency;
* ``time since <event>`` (s, 0 before the event): a slow transient that
  starts at an observed event: an unmodelled deployment load, bag or canopy
  mass, a calibration that drifts after it.

`signature_correlations` gives the Pearson correlation of a channel's
normalised residual with each signature over a window, with a p-value that
allows for the autocorrelation of both series: the effective sample size
n_eff = n (1 - r1 r2) / (1 + r1 r2) (r1, r2 the lag-1 autocorrelations;
Bartlett 1935, Bretherton et al. 1999), and t = r sqrt((n_eff - 2) / (1 - r^2))
against Student's t with n_eff - 2 degrees of freedom.  A smooth signature
(r2 near 1) against white residuals (r1 near 0) keeps n_eff near n; residuals
with serial correlation of their own lower it, as they must.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import t as student_t

from cpas_ocp.physics.parameters import param_name

if TYPE_CHECKING:
    from cpas_ocp.estimation.estimator import Fit, SensorResidual

# A signature whose spread in a window is below this fraction of its largest magnitude
# over the phase is constant there, and carries no shape to correlate with.
FLAT_FRACTION = 1e-9
# Fewest effective samples a correlation's p-value is computed with.
MIN_EFFECTIVE_SAMPLES = 3.0

POINTS_TO = {
    "dynamic_pressure": "a drag-area error in proportion to q (steady CdS, drag scale, "
                        "wake pressure recovery, air density)",
    "airspeed": "a speed-dependent error (wind, GPS velocity scale, Reynolds or Mach "
                "dependence of the drag)",
    "load_factor": "the vehicle's acceleration (accelerometer scale, GPS velocity lag, "
                   "inertial load of canopy and air mass)",
    "load_factor_rate": "a sensor lag or filter on the acceleration, or a compliance "
                        "that delays the load",
    "altitude": "an error that varies with height (a wind that changes with altitude, a "
                "wrong atmosphere)",
    "tension": "a load-cell gain that varies with the load (a nonlinear cell, a loss that "
               "grows with tension)",
    "cds": "an error in the level of the canopy's drag area (steady CdS, drag or "
           "load-cell scale)",
    "cds_rate": "added air mass, load-cell friction that follows the load's rate, or a "
                "wrong fill shape",
    "tension_rate": "a load-cell lag or rate-dependent fairlead friction",
    "stretch": "riser elasticity beyond the linear spring-damper, or a wrong riser frequency",
    "time_since": "a slow transient that starts at the event (deployment load, bag or "
                  "canopy mass, a drifting calibration)",
}


@dataclass(frozen=True, eq=False)
class Signature:
    """A candidate signature: values (in `unit`) on the fit's grid `t` (s), and the missing
    physics a residual shaped like it points to."""

    name: str
    unit: str
    points_to: str
    t: np.ndarray
    values: np.ndarray

    def at(self, t: np.ndarray) -> np.ndarray:
        """Linear interpolation to the times `t` (s)."""
        return np.interp(t, self.t, self.values)


@dataclass(frozen=True)
class Correlation:
    """Pearson correlation r of a normalised residual with a signature over a window, its
    two-sided p-value on n_eff effective samples out of `samples`."""

    signature: str
    points_to: str
    r: float
    p_value: float
    samples: int
    effective_samples: float


def signatures(fit: Fit) -> list[Signature]:
    """The candidate signatures of a fit, on its shooting grid (see the module docstring)."""
    q = fit.quantities()
    t = fit.t
    out: list[Signature] = []

    def add(name: str, unit: str, kind: str, values: np.ndarray) -> None:
        out.append(Signature(name, unit, POINTS_TO[kind], t, np.asarray(values, dtype=float)))

    for name, unit in (("dynamic_pressure", "Pa"), ("airspeed", "m/s"), ("load_factor", "g"),
                       ("altitude", "m")):
        if name in q:
            add(name, unit, name, q[name])
    if "load_factor" in q:
        add("d(load_factor)/dt", "g/s", "load_factor_rate", np.gradient(q["load_factor"], t))
    for chute in fit.test.parachutes:
        cds = q.get(param_name("cds", chute.name))
        if cds is not None:
            add(param_name("cds", chute.name), "m^2", "cds", cds)
            add(param_name("dCdS/dt", chute.name), "m^2/s", "cds_rate", np.gradient(cds, t))
        tension = q.get(param_name("tension", chute.name))
        if tension is not None:
            add(param_name("tension", chute.name), "N", "tension", tension)
            add(param_name("dT/dt", chute.name), "N/s", "tension_rate",
                np.gradient(tension, t))
        stretch = q.get(param_name("stretch", chute.name))
        if stretch is not None:
            add(param_name("stretch", chute.name), "m", "stretch", stretch)
    for event in fit.test.events:
        index = (event.parachute,) if event.stage is None else (event.parachute, event.stage)
        add(f"time since {param_name(event.name, *index)}", "s", "time_since",
            np.maximum(t - event.time, 0.0))
    return out


def lag1_autocorrelation(x: np.ndarray) -> float:
    """Lag-1 sample autocorrelation of a series about its mean (0 for a constant one)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    denom = float(x @ x)
    return float(x[1:] @ x[:-1]) / denom if denom > 0 else 0.0


def effective_samples(n: int, r1: float, r2: float) -> float:
    """n (1 - r1 r2) / (1 + r1 r2), kept within [MIN_EFFECTIVE_SAMPLES, n]."""
    rr = r1 * r2
    return float(np.clip(n * (1.0 - rr) / (1.0 + rr), MIN_EFFECTIVE_SAMPLES, n))


def correlation_p_value(r: float, n_eff: float) -> float:
    """Two-sided p-value of a Pearson r on n_eff effective samples (Student's t, n_eff - 2)."""
    if abs(r) >= 1.0:
        return 0.0
    stat = abs(r) * np.sqrt((n_eff - 2.0) / (1.0 - r * r))
    return float(2.0 * student_t.sf(stat, n_eff - 2.0))


def signature_correlations(residual: SensorResidual, signatures: Sequence[Signature],
                           t0: float, t1: float) -> list[Correlation]:
    """Correlation of the residual's normalised values with each signature over the samples
    in [t0, t1] (s), sorted by |r|, largest first.

    Signatures constant over the window are left out; fewer than 3 samples give none.
    """
    sel = (residual.t >= t0) & (residual.t <= t1)
    n = int(sel.sum())
    if n < MIN_EFFECTIVE_SAMPLES:
        return []
    e = residual.normalised[sel] - np.mean(residual.normalised[sel])
    ee = float(e @ e)
    if ee <= 0.0:
        return []
    r1 = lag1_autocorrelation(e)
    out: list[Correlation] = []
    for sig in signatures:
        s = sig.at(residual.t[sel])
        s = s - np.mean(s)
        scale = float(np.max(np.abs(sig.values))) if sig.values.size else 0.0
        if float(np.max(np.abs(s))) <= FLAT_FRACTION * scale or not np.any(s):
            continue
        r = float(np.clip((e @ s) / np.sqrt(ee * float(s @ s)), -1.0, 1.0))
        n_eff = effective_samples(n, r1, lag1_autocorrelation(s))
        out.append(Correlation(sig.name, sig.points_to, r, correlation_p_value(r, n_eff), n,
                               n_eff))
    return sorted(out, key=lambda c: abs(c.r), reverse=True)
