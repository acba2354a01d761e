"""Rocket flights whose recovery goes right or wrong, for the deployment forensics' tests.

A vertical point mass (boost, coast, descent) under gravity and drag, m dv/dt = T - m g -
1/2 rho (v - w) |v - w| CdS(t), with the air's vertical motion w an Ornstein-Uhlenbeck
process (seeded; `AIR_SIGMA_M_S`, `AIR_TAU_S`), each canopy's drag area growing linearly
over its fill from `LINE_STRETCH_S` after its charge to the area it reaches (0 for a
canopy that does not open, a streamer's few hundredths of a square metre, or the full
area).  The altimeter reads the height above the pad with white noise and the charge's
pressure pulse; the axial accelerometer (specific force along the vertical body, one g
subtracted) reads with white noise and an offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cpas_ocp.physics.atmosphere import SiteAtmosphere
from cpas_ocp.physics.units import G0

SITE = SiteAtmosphere.from_surface_density(1401.0, 86300.0, 1.001, 0.008)
H_TABLE = np.arange(-50.0, 8000.0, 1.0)
RHO_TABLE = np.asarray(SITE.density(SITE.elevation_m + H_TABLE), dtype=float)
MASS = 16.9  # kg, the vehicle after burnout with its canopies
BODY_CDS = 0.02  # m^2, the airframe's drag area (nose first: about 125 m/s falling)
THRUST_N, BURN_S = 2500.0, 3.0
LINE_STRETCH_S = 0.3  # s from a charge to its canopy starting to fill
AIR_SIGMA_M_S, AIR_TAU_S = 0.3, 30.0  # the air's vertical motion: sigma (m/s), time (s)
BARO_SIGMA_M = 0.3  # altimeter noise (m)
ACCEL_SIGMA, ACCEL_OFFSET = 0.3, 0.2  # accelerometer noise and offset (m/s^2)
DT = 0.025  # integration step (s)


def density(h: np.ndarray) -> np.ndarray:
    """Air density (kg/m^3) at heights `h` (m above the pad)."""
    return np.interp(h, H_TABLE, RHO_TABLE)


@dataclass(frozen=True)
class Chute:
    """A canopy: the drag area it reaches (m^2), its fill time (s), its diameter (m), and
    its charge: `delay_s` after apogee, or where the descent passes `height_m` (m).  A canopy
    that hangs (in its bag, tangled) streams at `streaming_cds` (m^2) from its line
    stretch for `hang_s` (s) before it fills."""

    cds: float
    fill_s: float
    diameter: float
    delay_s: float | None = None
    height_m: float | None = None
    hang_s: float = 0.0
    streaming_cds: float = 0.0

    def drag_area(self, since_charge: float) -> float:
        """The drag area (m^2) `since_charge` s after the charge."""
        out = since_charge - LINE_STRETCH_S
        if out < 0.0:
            return 0.0
        grow = min(max((out - self.hang_s) / self.fill_s, 0.0), 1.0)
        return self.streaming_cds + (self.cds - self.streaming_cds) * grow


DROGUE = Chute(0.467, 0.6, 0.61, delay_s=1.0)
MAIN = Chute(5.78, 1.2, 1.83, height_m=450.0)


@dataclass(frozen=True)
class Recovery:
    """A flown recovery: logged times (s), the altimeter's heights (m), the accelerometer's
    axial readings (m/s^2, one g subtracted), the true heights (m), the events (s: burnout,
    apogee, each canopy's charge, landed)."""

    t: np.ndarray
    height: np.ndarray
    accel: np.ndarray
    truth: np.ndarray
    events: dict[str, float] = field(default_factory=dict)


def fly_recovery(seed: int, chutes: dict[str, Chute], body_cds: float = BODY_CDS,
                 rate_hz: float = 20.0, end_s: float | None = None,
                 air_sigma: float = AIR_SIGMA_M_S) -> Recovery:
    """Fly the rocket with `chutes` (deployed in their triggers' order), logging at
    `rate_hz` until 5 s after touchdown or `end_s` (s)."""
    rng = np.random.default_rng(seed)
    decay = np.exp(-DT / AIR_TAU_S)
    kick = air_sigma * np.sqrt(1.0 - decay**2)
    t, h, v, w = -1.0, 0.0, 0.0, air_sigma * rng.normal()
    events: dict[str, float] = {"burnout": BURN_S}
    rows = []
    landed = None
    while landed is None or t < landed + 5.0:
        thrust = THRUST_N if 0.0 <= t < BURN_S else 0.0
        cds = body_cds + sum(c.drag_area(t - events[n]) for n, c in chutes.items()
                             if n in events)
        air = v - w
        drag = -0.5 * float(density(h)) * air * abs(air) * cds
        flying = t >= 0.0 and landed is None
        f = (thrust + drag) / MASS if flying else G0
        rows.append((t, h, f))
        if flying:
            v += (f - G0) * DT
            h += v * DT
        w = decay * w + kick * rng.normal()
        t = round(t + DT, 6)
        if "apogee" not in events and t > BURN_S and v < 0.0:
            events["apogee"] = t
        for name, c in chutes.items():
            if name in events or "apogee" not in events:
                continue
            if (c.delay_s is not None and t >= events["apogee"] + c.delay_s) or (
                    c.height_m is not None and h <= c.height_m):
                events[name] = t
        if landed is None and "apogee" in events and h <= 0.0:
            h, v, landed = 0.0, 0.0, t
            events["landed"] = t
        if end_s is not None and t > end_s:
            break
    every = round(1.0 / (rate_hz * DT))
    a = np.array(rows)[::every]
    times, truth, force = a[:, 0], a[:, 1], a[:, 2]
    height = truth + rng.normal(0.0, BARO_SIGMA_M, times.size)
    accel = force - G0 + ACCEL_OFFSET + rng.normal(0.0, ACCEL_SIGMA, times.size)
    for name in chutes:
        if name in events:
            k = int(np.searchsorted(times, events[name]))
            height[k:k + 2] += (60.0, 25.0)  # the charge's gas at the static port
    return Recovery(times, height, accel, truth, events)


FILTER_OMEGA, FILTER_ZETA = 2.0, 0.2  # a recorder's altitude filter: rad/s, damping ratio
FILTER_STEP_M = 0.084  # its exported altitude's resolution (m)


def filtered_altitude(t: np.ndarray, z: np.ndarray, omega: float = FILTER_OMEGA,
                      zeta: float = FILTER_ZETA, step_m: float = FILTER_STEP_M) -> np.ndarray:
    """What a flight computer's filtered export writes of the altitude readings `z` (m) at
    times `t` (s): a position-velocity tracker (alpha-beta, alpha = 2 zeta omega dt, beta =
    (omega dt)^2: a second-order loop of natural frequency `omega` rad/s and damping
    `zeta`), rounded to `step_m`.  It follows a steady descent without lag; where the
    vehicle stops at its impact, the estimate's speed carries it below the ground by about
    the descent rate over omega and rebounds above it, and its noise is correlated over
    about 1/omega s."""
    x, v = float(z[0]), 0.0
    out = np.empty_like(z)
    out[0] = x
    for k in range(1, z.size):
        dt = t[k] - t[k - 1]
        x_pred = x + v * dt
        r = z[k] - x_pred
        x = x_pred + 2.0 * zeta * omega * dt * r
        v = v + omega**2 * dt * r
        out[k] = x
    return np.round(out / step_m) * step_m
