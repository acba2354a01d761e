"""A later canopy's opening as the accelerometer reads it: the largest reading the
canopies' drag can give (`drag_ceiling`), above which the shock cord's snatch is left out,
and the opening-load peak that times the canopy's full open (`opening_peak`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from cpas_ocp.io.import_events import EJECTION_EXCLUDE_S, EVENT_SIGMA_S
from cpas_ocp.io.log_noise import RATE_WINDOW_S, STEADY_RATE_S, local_slope
from cpas_ocp.physics.units import G0

MIN_ACCEL_SIGMA = 0.1  # floor of the accelerometer noise sigma (m/s^2)


OPENING_WINDOW_S = 3.0  # an opening-load peak is looked for this long after the charge (s)


OPENING_BASELINE_S = 5.0  # the steady reading before a charge is taken over this long (s)


OPENING_PEAK_SIGMAS = 5.0  # a peak counts when this many scatter sigmas off the steady reading


def drag_ceiling(t: np.ndarray, height: np.ndarray, density: np.ndarray, t_charge: float,
                 t_settled: float, t_next: float) -> float | None:
    """The largest axial reading (m/s^2, one g subtracted) the canopies' drag can give in
    the opening that follows a charge at `t_charge`, from the altimeter alone.

    Once settled (from `t_settled`, over STEADY_RATE_S or to `t_next`) the open
    canopies carry the weight at the descent rate v_s, so their full drag area is
    2 m g / (rho_s v_s^2).  No opening pulls more than that area at the speed v_c
    the vehicle had at the charge (the rate over RATE_WINDOW_S before it): a
    specific force of g (rho_c v_c^2) / (rho_s v_s^2), and an axial reading of
    at most that less one g (the axis's cosine to the force is at most 1).  A
    reading above it is the shock cord's snatch, the elastic cord giving back the
    energy it stored as the canopy stopped ahead of the vehicle, which no drag
    model makes.  `height` (m) and `density` (kg/m^3) are the altimeter's
    samples at times `t`.  None where the rates cannot be told."""
    early = t_charge - EVENT_SIGMA_S
    v_c = -local_slope(t, height, early - RATE_WINDOW_S, early)
    end = min(t_settled + STEADY_RATE_S, t_next)
    v_s = -local_slope(t, height, t_settled, end)
    if not (v_c > 0.0 and v_s > 0.0):
        return None
    at_charge = (t >= early - RATE_WINDOW_S) & (t <= early)
    settled = (t >= t_settled) & (t <= end)
    ratio = float(np.mean(density[at_charge]) / np.mean(density[settled]))
    return G0 * ratio * (v_c / v_s) ** 2 - G0


def descent_load_factor_peak(accel: pd.DataFrame, t_from: float, t_to: float
                             ) -> tuple[float, float]:
    """Largest axial specific force (g) between `t_from` and `t_to` (s) and its time (s).

    The logger's axial acceleration has 1 g subtracted, so the specific force
    along the axis is (a + g0) / g0; its magnitude is a lower bound on the
    load factor (the axis need not point along the riser)."""
    sel = accel[(accel["time"] >= t_from) & (accel["time"] <= t_to)]
    if sel.empty:
        raise ValueError(f"no accelerometer samples in [{t_from}, {t_to}] s")
    f = np.abs(sel["acceleration"].to_numpy() + G0) / G0
    k = int(np.argmax(f))
    return float(f[k]), float(sel["time"].iloc[k])


def opening_peak(accel: pd.DataFrame, t_charge: float) -> tuple[float, float] | None:
    """(time, sigma) in s of the opening-load peak after the charge at `t_charge` (s): the
    largest axial specific force from `EJECTION_EXCLUDE_S` to `OPENING_WINDOW_S` after it
    (`descent_load_factor_peak`; the charge's own jolt comes first), sigma the median
    sample interval.  None where the peak stands fewer than `OPENING_PEAK_SIGMAS` scatter
    sigmas (1.4826 MAD) off the median reading of the `OPENING_BASELINE_S` before the
    charge, or where the accelerometer has too few samples there to tell."""
    lo, hi = t_charge + EJECTION_EXCLUDE_S, t_charge + OPENING_WINDOW_S
    before = accel[(accel["time"] >= t_charge - OPENING_BASELINE_S)
                   & (accel["time"] < t_charge - EVENT_SIGMA_S)]["acceleration"].to_numpy()
    after = accel["time"][(accel["time"] >= lo) & (accel["time"] <= hi)].to_numpy()
    if before.size < 10 or after.size < 3:
        return None
    peak, t_peak = descent_load_factor_peak(accel, lo, hi)
    steady = float(np.median(before))
    scatter = max(MIN_ACCEL_SIGMA, 1.4826 * float(np.median(np.abs(before - steady))))
    if abs(peak * G0 - abs(steady + G0)) < OPENING_PEAK_SIGMAS * scatter:
        return None
    return t_peak, float(np.median(np.diff(after)))
