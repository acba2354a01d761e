"""Did each canopy of a rocket's recovery open, when, and how fully: forensics from the log.

Amateur rockets often fail to recover: a drogue that never opened (a ballistic descent at
tens of m/s under the airframe's own drag), a streamer or a partly open canopy (a drag
area far below its diameter's), a main that deployed and did not inflate (the descent
rate does not change at its charge).  `deployment_forensics` answers for each canopy, in
deployment order, from the altimeter's heights, the air's density, the descent mass, the
canopies' deployment times and diameters, and the airframe's drag area (from the coast,
`coast_drag_area`, or the card):

* the drag area the settled descent under it needs (`settled_descent`).  At terminal
  speed the drag carries the weight: CdS = 2 m g_eff / (rho v^2), with the descent rate v
  from a straight-line fit of the *density-scaled height* s(h) = int sqrt(rho(h) /
  rho_ref) dh against time (under a constant drag area the terminal rate scales as
  rho^-1/2, so s falls linearly in time, v = -ds/dt the rate at the reference density
  rho_ref, that of the fitted samples' mean height).  g_eff = g + v^2 / (2 H_rho), H_rho
  the density's scale height: the vehicle slows as the air thickens, and the drag
  carries that deceleration too (0.5 % at 26 m/s, 5 % at 100 m/s).  The sigma:

      sigma_v^2 = sigma_h^2 tau / sum_i (t_i - t_mean)^2 + sigma_w^2,
      sigma_CdS = CdS * 2 sigma_v / v,

  sigma_h the altimeter's noise (the larger of the stated one and the fit's residual
  scatter), tau the residuals' integrated autocorrelation time in samples
  (`log_noise.integrated_time`: a noise correlated over tau samples carries a tau-th of
  the information), and sigma_w (`air_sigma`, default `AIR_SIGMA_M_S` = 0.3 m/s) the mean
  vertical air motion over the descent: subsidence and thermals move the ground-relative
  rate by a few tenths of m/s, which no fit of one descent can tell from the canopy.
  The mass's and the density's errors scale every drag area alike (the coast's too) and
  are not in the sigma: the comparisons below do not see them;
* the airframe's own drag area: in the coast after burnout the vehicle decelerates by
  g + q CdS_V / m (`coast_drag_area`), else the card's ``vehicle.forebody_cds``, else None;
* each canopy's own drag area: the total under it less the total open before it (the
  airframe's for the first canopy; the earlier canopies' settled descent for a later one,
  which is the two-sample test of the rates before and after its charge, scaled to one
  density), with both sigmas in quadrature.  The airframe's drag area stands as the
  "nothing opened" total with a model allowance `AIRFRAME_MODEL_REL` added: the coast flies
  nose first at 100-250 m/s, a ballistic descent at another attitude and speed.

The verdict (one-sided z-tests at the family-wise level `alpha` over the canopies, by
Bonferroni: two tests per canopy), with F = `FLOOR_CD` pi D^2 / 4 the least drag area an
open canopy of diameter D gives:

* ``not_opened``: the own drag area is below F (rejected: "open at F or more") and not
  above 0 (not rejected: "nothing opened"); or, where the drag area before is unknown
  (no coast, no card), below F alone (the sentence says a streamer cannot be told apart);
* ``partial``: above 0 and below F, both significant (a streamer, a canopy partly open,
  or a tangled canopy under a tumbling airframe: drag, but far less than an open canopy's);
* ``opened``: not below F, and above 0 (or above F) significantly; with the time the
  descent rate changed (`rate_change_time`) where there is a settled descent before the
  charge, and a flag where the drag area is more than `MAX_CD` pi D^2 / 4 can give (a
  larger canopy was out: the main, at apogee?).  The first canopy's descent may take hold
  late: where the heights after its charge fall `LATE_RATE_RATIO` times faster than its
  settled descent up to a corner more than `LATE_OPENING_S` after the charge
  (`late_opening`), the canopy hung (in its bag, streaming, tangled with a separated part)
  and opened at that corner; the fall before it and the drag area that fall needs are
  said, for the fit to start the canopy there (`rocket_model.late_openings`).  A later
  canopy whose charge changes nothing after such a flag is ``undetermined`` (it may have
  been out already);
* ``undetermined``: the log ends before the charge or too soon after it (a settled
  descent of `MIN_SETTLED_S` and `log_noise.MIN_DESCENT_SAMPLES` samples), or the noise
  lets both nulls stand.  Where the canopy's diameter is unknown, "below F" is replaced by
  "below the drag area open before it" (a canopy that does not double the drag area slows
  the descent by under 29 %: it recovers nothing).

Why Cd 0.3 on pi D^2 / 4: open canopies have a Cd on their nominal area of 0.75-0.8 (flat
circular) to 1.5-2.2 (hobby-rocket canopies as sold); a streamer or a squidding canopy
gives a few tenths at most.  Half the least open value keeps a canopy open in rough air
(Cd 0.5) from being called partial, and calls partial what gives a fifth of a typical
hobby canopy's drag.

Inputs are numpy arrays in SI: times (s), heights (m, geometric: an altimeter's pressure
altitude converted through the site atmosphere; pressure altitude itself reads the rate
low by rho / rho_standard, a few per cent), a density callable of those heights (kg/m^3),
the descent mass (kg).  Outputs are frozen dataclasses with a plain sentence each.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import norm

from cpas_ocp.io.import_events import EJECTION_EXCLUDE_S
from cpas_ocp.io.log_noise import (
    MIN_DESCENT_SAMPLES,
    integrated_time,
    local_slope,
    settled_time,
)
from cpas_ocp.physics.effects.canopy_inflation import MAX_CD
from cpas_ocp.physics.units import G0
from cpas_ocp.precision import rounded, with_sigma

Density = Callable[[np.ndarray], np.ndarray]

AIR_SIGMA_M_S = 0.3  # default mean vertical air motion over a descent (m/s): see the docstring

FLOOR_CD = 0.3  # least Cd on pi D^2 / 4 of an open canopy (half the least open value)

AIRFRAME_MODEL_REL = 0.15  # the airframe's descent drag area against its coast's (relative)

ALPHA = 0.01  # family-wise level of the verdicts over all canopies

MIN_SETTLED_S = 4.0  # least settled descent fitted under a canopy (s)

RELAXATION_TIMES = 3.0  # the fit starts this many speed relaxation times (v / 2g) after settling


COAST_WINDOW_S = 1.0  # the coast's height is fitted by a quadratic in windows this long (s)

COAST_SPEEDS_M_S = (40.0, 250.0)  # coast windows within these vertical speeds (subsonic)

MIN_COAST_WINDOWS = 4  # least coast windows for an airframe drag area

# The coast's drag area's systematic sigma (relative): the vertical speed stands for the path
# speed (1.5 % at 10 degrees off the vertical, 3 % with the accelerometer), the drag
# coefficient changes with the Mach number below 250 m/s, an accelerometer's scale errs by
# a per cent or two.
COAST_SYSTEMATIC_REL = 0.03

COAST_AGREE_Z = 3.0  # the accelerometer's coast drag area this many sigmas off: left out

TREND_Z = 3.0  # the halves of a settled descent differ by this many sigmas: not settled

HINGE_BEFORE_S = 5.0  # the rate-change fit looks this far before a charge (s) ...

HINGE_AFTER_S = 5.0  # ... and this far past the settled time after it

# A canopy fills within a second or two of its charge; the descent's corner this long after
# the first canopy's charge, from a fall this many times faster than the settled descent,
# is a late opening (`late_opening`).
LATE_OPENING_S = 2.0

LATE_RATE_RATIO = 1.5

VERDICTS = ("opened", "partial", "not_opened", "undetermined")


@dataclass(frozen=True)
class Canopy:
    """A canopy as the import knows it: its name, deployment time (s; None where the log
    shows no charge for it) with its sigma (s), and its diameter D (m; None where the card
    gives none)."""

    name: str
    deploy_time: float | None
    deploy_sigma: float = 0.1
    diameter: float | None = None


@dataclass(frozen=True)
class DragArea:
    """A drag area (m^2) with its sigma (m^2) and where it came from (``coast``, ``card``,
    ``descent``)."""

    value: float
    sigma: float
    source: str


@dataclass(frozen=True)
class SettledDescent:
    """The settled descent fitted under a canopy: the span fitted (s), the descent rate and
    its sigma (m/s) at the reference height (m, the fitted samples' mean) where the air has
    `density` (kg/m^3), the drag area it needs and its sigma (m^2), the samples fitted, and
    ``settled``, or ``accelerating`` / ``decelerating`` where the rate still changed
    (`settled_descent`)."""

    t_from: float
    t_to: float
    rate: float
    rate_sigma: float
    height: float
    density: float
    drag_area: float
    drag_area_sigma: float
    samples: int
    trend: str = "settled"


@dataclass(frozen=True)
class CanopyForensics:
    """What the log says of one canopy.

    verdict: one of `VERDICTS`; sentence: what a rocketry user can act on.  drag_area: the
    total the settled descent under it needs; own: that less the total open before it
    (`before`: the airframe's or the earlier canopies', None where unknown); floor: F =
    FLOOR_CD pi D^2 / 4 (or the drag area before, without a diameter); z_opened, p_opened:
    the test of "nothing opened" (own <= 0); z_short, p_short: of "open at F or more"
    (own >= F); above_diameter: the own drag area is significantly more than MAX_CD pi D^2
    / 4; t_open, t_open_sigma: when the descent rate changed (s); rate_before: the settled
    descent before the charge (a later canopy's); fall_before: the drag area (m^2) the
    fall from the charge to a late opening needs (`late_opening`; None where the canopy
    took hold at its charge)."""

    name: str
    verdict: str
    sentence: str
    deploy_time: float | None
    descent: SettledDescent | None
    own: DragArea | None
    before: DragArea | None
    floor: float | None
    z_opened: float | None
    p_opened: float | None
    z_short: float | None
    p_short: float | None
    above_diameter: bool
    t_open: float | None
    t_open_sigma: float | None
    rate_before: SettledDescent | None
    fall_before: DragArea | None = None

    def as_dict(self) -> dict[str, Any]:
        """The verdict, its sentence and the numbers it rests on (SI), for ``import.json``."""
        def area(a: DragArea | None) -> dict[str, Any] | None:
            return None if a is None else {"value_m2": a.value, "sigma_m2": a.sigma,
                                           "source": a.source}
        descent = self.descent
        return {"verdict": self.verdict, "sentence": self.sentence,
                "deploy_time_s": self.deploy_time,
                "descent_rate_m_s": None if descent is None else descent.rate,
                "descent_rate_sigma_m_s": None if descent is None else descent.rate_sigma,
                "drag_area_m2": None if descent is None else descent.drag_area,
                "drag_area_sigma_m2": None if descent is None else descent.drag_area_sigma,
                "own": area(self.own), "before": area(self.before),
                "p_opened": self.p_opened, "p_short": self.p_short,
                "above_diameter": self.above_diameter,
                "t_open_s": self.t_open, "t_open_sigma_s": self.t_open_sigma,
                "fall_before_m2": None if self.fall_before is None else self.fall_before.value}


@dataclass(frozen=True)
class Forensics:
    """Each canopy's forensics in deployment order, the airframe's drag area (None where
    neither the coast nor the card gives one), the family-wise level and the one-sided
    critical z of each test."""

    canopies: tuple[CanopyForensics, ...]
    airframe: DragArea | None
    alpha: float
    z_critical: float

    def sentences(self) -> list[str]:
        return [c.sentence for c in self.canopies]

    def __getitem__(self, name: str) -> CanopyForensics:
        for c in self.canopies:
            if c.name == name:
                return c
        raise KeyError(name)


def _rho(density: Density, h: np.ndarray | float) -> np.ndarray:
    return np.asarray(density(np.atleast_1d(np.asarray(h, dtype=float))), dtype=float).ravel()


def scaled_height(density: Density, h: np.ndarray, rho_ref: float) -> np.ndarray:
    """s(h) = int_h0^h sqrt(rho(h') / rho_ref) dh' (m), h0 the lowest of `h`: at a terminal
    descent under a constant drag area, s falls linearly in time at the rate the vehicle
    has where the air has `rho_ref` (trapezoids on a grid of at most 5 m)."""
    lo, hi = float(np.min(h)), float(np.max(h))
    grid = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / 5.0)) + 1))
    root = np.sqrt(_rho(density, grid) / rho_ref)
    s = np.r_[0.0, np.cumsum(0.5 * (root[1:] + root[:-1]) * np.diff(grid))]
    return np.interp(h, grid, s)


def _scale_height(density: Density, h: float) -> float:
    """The density's scale height -rho / (d rho / dh) at `h` (m)."""
    lo, hi = _rho(density, np.array([h - 100.0, h + 100.0]))
    return 200.0 / math.log(lo / hi) if lo > hi > 0.0 else math.inf


def _line(ts: np.ndarray, s: np.ndarray, noise_sigma: float) -> tuple[float, float]:
    """Descent rate (-ds/dt, m/s) of a straight line through (ts, s) and its noise sigma
    sigma_h sqrt(tau / sum (t - t_mean)^2) (module docstring), no air motion in it."""
    dt = ts - ts.mean()
    sxx = float(np.dot(dt, dt))
    slope = float(np.dot(dt, s - s.mean()) / sxx)
    resid = s - s.mean() - slope * dt
    scatter = math.sqrt(float(np.dot(resid, resid)) / max(1, resid.size - 2))
    tau = max(1.0, integrated_time(resid))
    return -slope, max(noise_sigma, scatter) * math.sqrt(tau / sxx)


def settled_descent(t: np.ndarray, height: np.ndarray, density: Density, mass: float,
                    t_from: float, t_to: float, noise_sigma: float = 0.0,
                    air_sigma: float = AIR_SIGMA_M_S,
                    z_trend: float = TREND_Z) -> SettledDescent | None:
    """The settled descent under the canopies open from `t_from` to `t_to` (s) and the drag
    area it needs (see the module docstring for the fit and its sigma).

    The descent has settled at `log_noise.settled_time` (its local rate within 1.25 of the
    steady one); the fit starts `RELAXATION_TIMES` speed relaxation times v / (2 g) later,
    when what is left of the opening's or the fall's speed is a few per cent (at most half
    the settled span later).  Where the density-scaled rates of the fit's two halves still
    differ by more than `z_trend` sigmas (each half's noise and the air's motion,
    sqrt(2) `air_sigma` between them), the vehicle was still speeding up or slowing down:
    the later half is taken, and so on while that is long enough; where the last half
    still shows a trend it is returned with `trend` ``accelerating`` (its drag area an
    upper bound: the terminal rate is faster) or ``decelerating`` (a lower bound).
    `noise_sigma`: the altimeter's (m).  None where fewer than `MIN_DESCENT_SAMPLES`
    samples or `MIN_SETTLED_S` are left, or the vehicle does not fall."""
    span = (t >= t_from) & (t <= t_to)
    if span.sum() < MIN_DESCENT_SAMPLES or t_to - t_from < MIN_SETTLED_S:
        return None
    t_settled = settled_time(t, height, t_from, t_to)
    late = -local_slope(t, height, 0.5 * (t_settled + t_to), t_to)
    relax = RELAXATION_TIMES * late / (2.0 * G0) if late > 0.0 else 0.0
    start = min(t_settled + relax, 0.5 * (t_settled + t_to))
    sel = (t >= start) & (t <= t_to)
    if sel.sum() < MIN_DESCENT_SAMPLES or t_to - start < MIN_SETTLED_S:
        return None
    ts, hs = t[sel], height[sel]
    h_ref = float(np.mean(hs))
    rho_ref = float(_rho(density, h_ref)[0])
    s = scaled_height(density, hs, rho_ref)
    rate, sigma_fit = _line(ts, s, noise_sigma)
    trend = "settled"
    while True:  # halve the span while its halves' rates differ: the later half settled
        half = ts >= 0.5 * (ts[0] + ts[-1])
        if min(half.sum(), (~half).sum()) < MIN_DESCENT_SAMPLES // 2:
            break
        (v1, s1), (v2, s2) = _line(ts[~half], s[~half], noise_sigma), \
            _line(ts[half], s[half], noise_sigma)
        if abs(v2 - v1) <= z_trend * math.sqrt(s1**2 + s2**2 + 2.0 * air_sigma**2):
            trend = "settled"
            break
        trend = "accelerating" if v2 > v1 else "decelerating"
        if half.sum() < MIN_DESCENT_SAMPLES or ts[-1] - ts[half][0] < MIN_SETTLED_S:
            break
        ts, hs = ts[half], hs[half]
        h_ref = float(np.mean(hs))
        rho_ref = float(_rho(density, h_ref)[0])
        s = scaled_height(density, hs, rho_ref)
        rate, sigma_fit = _line(ts, s, noise_sigma)
    if not rate > 0.0:
        return None
    rate_sigma = math.hypot(sigma_fit, air_sigma)
    g_eff = G0 + rate**2 / (2.0 * _scale_height(density, h_ref))
    area = 2.0 * mass * g_eff / (rho_ref * rate**2)
    return SettledDescent(float(ts[0]), float(ts[-1]), rate, rate_sigma, h_ref, rho_ref,
                          area, area * 2.0 * rate_sigma / rate, int(ts.size), trend)


def coast_drag_area(t: np.ndarray, height: np.ndarray, density: Density, mass: float,
                    t_burnout: float | None = None, t_apogee: float | None = None,
                    accel: tuple[np.ndarray, np.ndarray] | None = None,
                    speeds: tuple[float, float] = COAST_SPEEDS_M_S) -> DragArea | None:
    """The airframe's drag area (m^2) from its coast: after burnout it decelerates by
    dv/dt = -(g + rho v^2 CdS_V / (2 m)).

    The coast (from `t_burnout`, or the altimeter's fastest climb, to `t_apogee`, or its
    highest sample) is cut into windows of `COAST_WINDOW_S`; a quadratic fitted to each
    window's heights gives its vertical speed v and acceleration a at the window's centre,
    and windows with v within `speeds` (m/s: enough drag to measure, below the transonic
    rise of Cd) give y = -(a + g) against x = rho v^2 / (2 m): CdS_V = sum x y / sum x^2,
    its sigma the windows' residual scatter over sqrt(sum x^2) (the windows share no
    samples: independent).  With `accel` (times s, axial readings m/s^2 with one g
    subtracted: -(D/m) - g in the coast) each window's mean reading gives y = -(a_axial +
    g) = CdS_V x + b, b the accelerometer's offset; both sensors are weighed by their own
    residual scatter in one least-squares fit, unless the accelerometer's own fit lies
    more than `COAST_AGREE_Z` sigmas off the altimeter's (its axis or scale is wrong).
    The vertical speed stands for the path speed: a coast at 10 degrees off the vertical
    reads CdS_V 1.5 % high (3 % with the accelerometer): `COAST_SYSTEMATIC_REL` of the
    value is added to the sigma in quadrature.  None where fewer than `MIN_COAST_WINDOWS`
    windows qualify."""
    if t_apogee is None:
        t_apogee = float(t[np.argmax(height)])
    if t_burnout is None:
        centres = np.arange(t[0] + 0.5, t_apogee - 0.5, 0.25)
        if centres.size == 0:
            return None
        climb = np.array([local_slope(t, height, c - 0.5, c + 0.5) for c in centres])
        if not np.isfinite(climb).any():
            return None
        t_burnout = float(centres[np.nanargmax(climb)])
    edges = np.arange(t_burnout, t_apogee - COAST_WINDOW_S + 1e-9, COAST_WINDOW_S)
    rows = []
    for lo in edges:
        w = (t >= lo) & (t < lo + COAST_WINDOW_S)
        if w.sum() < 6:
            continue
        c = lo + 0.5 * COAST_WINDOW_S
        c2, c1, c0 = np.polyfit(t[w] - c, height[w], 2)
        if not speeds[0] <= c1 <= speeds[1]:
            continue
        x = float(_rho(density, c0)[0]) * c1**2 / (2.0 * mass)
        y_accel = np.nan
        if accel is not None:
            wa = (accel[0] >= lo) & (accel[0] < lo + COAST_WINDOW_S)
            if wa.sum() >= 3:
                y_accel = -(float(np.mean(accel[1][wa])) + G0)
        rows.append((x, -(2.0 * c2 + G0), y_accel))
    if len(rows) < MIN_COAST_WINDOWS:
        return None
    x, y_baro, y_acc = (np.array(col) for col in zip(*rows, strict=True))
    area = float(np.dot(x, y_baro) / np.dot(x, x))
    s_baro = math.sqrt(float(np.sum((y_baro - area * x) ** 2)) / (x.size - 1))
    has_acc = np.isfinite(y_acc)
    if has_acc.sum() < MIN_COAST_WINDOWS:
        return DragArea(area, math.hypot(s_baro / math.sqrt(float(np.dot(x, x))),
                                         COAST_SYSTEMATIC_REL * area), "coast (altimeter)")
    baro_only = DragArea(area, math.hypot(s_baro / math.sqrt(float(np.dot(x, x))),
                                          COAST_SYSTEMATIC_REL * area), "coast (altimeter)")
    xa, ya = x[has_acc], y_acc[has_acc]
    fit_a, cov_a = np.polyfit(xa, ya, 1, cov="unscaled")
    s_acc = math.sqrt(float(np.sum((ya - np.polyval(fit_a, xa)) ** 2)) / max(1, xa.size - 2))
    s_acc = max(s_acc, 1e-6)
    sigma_a = math.hypot(s_acc * math.sqrt(float(cov_a[0, 0])), COAST_SYSTEMATIC_REL * fit_a[0])
    if abs(fit_a[0] - area) > COAST_AGREE_Z * math.hypot(sigma_a, baro_only.sigma):
        # The sensors disagree (an axis or a scale wrong): the altimeter's alone.
        return DragArea(area, baro_only.sigma, "coast (altimeter; the accelerometer's "
                        f"{fit_a[0]:.2g} m^2 disagrees)")
    design = np.r_[np.c_[x, np.zeros_like(x)], np.c_[xa, np.ones_like(xa)]]
    weights = np.r_[np.full(x.size, s_baro**-2), np.full(xa.size, s_acc**-2)]
    values = np.r_[y_baro, ya]
    normal = design.T @ (design * weights[:, None])
    beta = np.linalg.solve(normal, design.T @ (weights * values))
    cov = np.linalg.inv(normal)
    return DragArea(float(beta[0]), math.hypot(math.sqrt(float(cov[0, 0])),
                                               COAST_SYSTEMATIC_REL * float(beta[0])),
                    "coast (altimeter and accelerometer)")


CORNER_STEP_S = 0.02  # the corner search's first grid (s); the best refined to every sample


def rate_change_time(t: np.ndarray, height: np.ndarray, t_charge: float, t_to: float,
                     before_s: float = HINGE_BEFORE_S) -> tuple[float, float] | None:
    """When the descent rate changed after a charge at `t_charge` (s): the corner of two
    straight lines joined there, fitted to the heights from `before_s` before the
    charge to `t_to` (s), by least squares over corners at every sample from the charge
    on; its sigma the half-width of the corners whose residual sum exceeds the least by
    at most one noise variance (the residual variance times their integrated
    autocorrelation time).  The opening's deceleration is a curve: the corner marks its
    middle.  None with too few samples."""
    sel = (t >= t_charge - before_s) & (t <= t_to)
    ts, hs = t[sel], height[sel]
    corners = ts[(ts >= t_charge) & (ts <= t_to - 1.0)]
    if ts.size < MIN_DESCENT_SAMPLES or corners.size < 3:
        return None
    def hinge_residuals(c: float) -> np.ndarray:
        """The heights less their least-squares hinge with its corner at `c` (s)."""
        design = np.c_[np.ones_like(ts), np.minimum(ts - c, 0.0), np.maximum(ts - c, 0.0)]
        return hs - design @ np.linalg.lstsq(design, hs, rcond=None)[0]

    def hinge_rss(c: float) -> float:
        r = hinge_residuals(c)
        return float(np.dot(r, r))

    # Every sample of a fast log is a corner to try: on a grid CORNER_STEP_S apart first,
    # then every sample within two of its steps of the best (a 4 kHz log's 100,000 corners
    # each refitted to 100,000 samples would take minutes).
    step = float(np.median(np.diff(ts)))
    stride = max(1, int(CORNER_STEP_S / step))
    rss_of = {i: hinge_rss(corners[i]) for i in range(0, corners.size, stride)}
    best = min(rss_of, key=rss_of.__getitem__)
    for i in range(max(0, best - 2 * stride), min(corners.size, best + 2 * stride + 1)):
        if i not in rss_of:
            rss_of[i] = hinge_rss(corners[i])
    order = sorted(rss_of)
    corners, rss = corners[order], np.array([rss_of[i] for i in order])
    k = int(np.argmin(rss))
    c = corners[k]
    noise = rss[k] / max(1, ts.size - 3) * max(1.0, integrated_time(hinge_residuals(c)))
    near = corners[rss - rss[k] <= noise]
    return float(c), max(step, 0.5 * float(near.max() - near.min()))


def late_opening(t: np.ndarray, height: np.ndarray, density: Density, mass: float,
                 t_charge: float, descent: SettledDescent, t_to: float
                 ) -> tuple[float, float, float, DragArea] | None:
    """Where the first canopy deployed at `t_charge` (s) took hold late: the corner of the
    heights after the charge (`rate_change_time`, nothing before it: the apogee's top is no
    descent) up to `HINGE_AFTER_S` past its settled `descent` (or `t_to`), more than
    `LATE_OPENING_S` after the charge by three of its sigmas, with the fall before it (a
    line through the heights of the later half from the charge to the corner, short of its
    last half second: the
    vehicle speeds up after the charge) `LATE_RATE_RATIO` times faster than the settled
    rate.
    Returns the corner (s), its sigma (s), the fall's rate (m/s) and the drag area it
    needs, 2 m g / (rho v^2) at its mean height (m^2, its sigma from the line's scatter and
    `AIR_SIGMA_M_S`): what held the vehicle before the canopy opened (the airframe and the
    canopy streaming).  None where the canopy took hold at its charge."""
    found = rate_change_time(t, height, t_charge, min(t_to, descent.t_from + HINGE_AFTER_S),
                             before_s=0.0)
    # Late beyond doubt: three of the corner's sigmas short of it still past LATE_OPENING_S.
    if found is None or found[0] - 3.0 * found[1] - t_charge <= LATE_OPENING_S:
        return None
    # The fall's later half, short of the corner: the vehicle speeds up after the charge.
    fall = (t >= 0.5 * (t_charge + found[0])) & (t <= found[0] - 0.5)
    if fall.sum() < MIN_DESCENT_SAMPLES // 2:
        return None
    h_ref = float(np.mean(height[fall]))
    rho_ref = float(_rho(density, h_ref)[0])
    rate, sigma = _line(t[fall], scaled_height(density, height[fall], rho_ref), 0.0)
    if not rate > LATE_RATE_RATIO * descent.rate:
        return None
    sigma = math.hypot(sigma, AIR_SIGMA_M_S)
    area = 2.0 * mass * G0 / (rho_ref * rate**2)
    return found[0], found[1], rate, DragArea(area, area * 2.0 * sigma / rate, "fall")


def _p(z: float) -> float:
    return float(norm.sf(z))


def deployment_forensics(t: np.ndarray, height: np.ndarray, density: Density, mass: float,
                         canopies: Sequence[Canopy], t_end: float | None = None,
                         noise_sigma: float | Sequence[float] = 0.0,
                         airframe: DragArea | None = None,
                         coast: DragArea | None = None,
                         air_sigma: float = AIR_SIGMA_M_S, alpha: float = ALPHA
                         ) -> Forensics:
    """Each canopy's forensics (module docstring) from the altimeter's heights `height` (m,
    geometric) at times `t` (s), the air's `density` (kg/m^3) at those heights, the descent
    mass (kg), the `canopies` (any order), the descent's end `t_end` (s: touchdown less a
    margin, or the log's end; default the last sample) and the altimeter's noise sigma (m;
    one, or one per canopy in deployment order).  The airframe's drag area is `coast`'s
    (`coast_drag_area`) where given, else `airframe`'s (the card's ``forebody_cds``), else
    unknown."""
    t = np.asarray(t, dtype=float)
    height = np.asarray(height, dtype=float)
    t_end = float(t[-1]) if t_end is None else float(t_end)
    order = sorted(canopies, key=lambda c: math.inf if c.deploy_time is None else c.deploy_time)
    sigmas = ([float(noise_sigma)] * len(order) if np.isscalar(noise_sigma)
              else [float(s) for s in noise_sigma])  # type: ignore[union-attr]
    frame = coast if coast is not None else airframe
    z_c = float(norm.isf(alpha / (2 * max(1, len(order)))))
    charges = [c.deploy_time for c in order]
    out: list[CanopyForensics] = []
    before: DragArea | None = None
    if frame is not None:
        allowance = AIRFRAME_MODEL_REL * frame.value
        before = DragArea(frame.value, math.hypot(frame.sigma, allowance), frame.source)
    previous: SettledDescent | None = None
    out_already = False  # an earlier descent needed more than its canopies can give
    for k, chute in enumerate(order):
        t_dep = chute.deploy_time
        floor = FLOOR_CD * math.pi * chute.diameter**2 / 4.0 if chute.diameter else None
        if t_dep is None or t_dep >= t_end - MIN_SETTLED_S:
            why = ("the log shows no charge for it" if t_dep is None else
                   f"the log ends {max(0.0, t_end - t_dep):.1f} s after its charge at "
                   f"{t_dep:.1f} s" if t_dep < t_end else
                   f"the log ends at {t_end:.1f} s, before its charge at {t_dep:.1f} s")
            out.append(_undetermined(chute, floor, before, previous, why))
            previous = None
            before = None
            continue
        nxt = next((c for c in charges[k + 1:] if c is not None), None)
        t_to = t_end if nxt is None or nxt >= t_end else \
            nxt - 3.0 * order[k + 1].deploy_sigma - 0.1
        t_from = t_dep + 3.0 * chute.deploy_sigma + EJECTION_EXCLUDE_S
        descent = settled_descent(t, height, density, mass, t_from, t_to,
                                  sigmas[min(k, len(sigmas) - 1)], air_sigma)
        if descent is None:
            out.append(_undetermined(chute, floor, before, previous,
                                     f"too short a settled descent after its charge at "
                                     f"{t_dep:.1f} s ({max(0.0, t_to - t_from):.1f} s of log "
                                     "before the next charge or the end)"))
            previous, before = None, None
            continue
        out.append(_judge(chute, descent, before, previous, floor, z_c, out_already, t, height,
                          t_to, density, mass))
        verdict = out[-1]
        out_already = out_already or verdict.above_diameter
        previous = descent
        before = DragArea(descent.drag_area, descent.drag_area_sigma, "descent")
    return Forensics(tuple(out), frame, alpha, z_c)


def _undetermined(chute: Canopy, floor: float | None, before: DragArea | None,
                  previous: SettledDescent | None, why: str) -> CanopyForensics:
    return CanopyForensics(chute.name, "undetermined",
                           f"the {chute.name}: cannot tell whether it opened: {why}",
                           chute.deploy_time, None, None, before, floor, None, None, None,
                           None, False, None, None, previous)


def _judge(chute: Canopy, descent: SettledDescent, before: DragArea | None,
           previous: SettledDescent | None, floor: float | None, z_c: float,
           out_already: bool, t: np.ndarray, height: np.ndarray, t_to: float,
           density: Density, mass: float) -> CanopyForensics:
    """The verdict on one canopy whose settled descent was fitted (module docstring)."""
    name, total, s_total = chute.name, descent.drag_area, descent.drag_area_sigma
    if before is not None:
        own = DragArea(total - before.value, math.hypot(s_total, before.sigma), "descent")
    else:
        own = DragArea(total, s_total, "descent (the airframe's included)")
    z_opened = own.value / own.sigma if before is not None else None
    opened_at_all = z_opened is not None and z_opened > z_c
    cut = floor if floor is not None else (before.value if before is not None else None)
    z_short = (cut - own.value) / own.sigma if cut is not None else None
    short = z_short is not None and z_short > z_c
    if before is not None:
        verdict = ("partial" if opened_at_all else "not_opened") if short else \
            "opened" if opened_at_all else "undetermined"
    elif z_short is not None:
        verdict = "not_opened" if short else "opened" if -z_short > z_c else "undetermined"
    else:
        verdict = "undetermined"
    # A descent still speeding up needs less drag at its terminal rate: its drag area is an
    # upper bound, which can show a canopy short and nothing open, not that something opened;
    # one still slowing, a lower bound, which can show a canopy open, not short.
    if (descent.trend == "accelerating" and verdict in ("opened", "partial")) or (
            descent.trend == "decelerating" and verdict in ("partial", "not_opened")):
        verdict = "undetermined"
    bound = MAX_CD * math.pi * chute.diameter**2 / 4.0 if chute.diameter else None
    above = bound is not None and (own.value - bound) / own.sigma > z_c
    already = out_already and not opened_at_all and verdict in ("not_opened", "undetermined")
    if already:
        verdict = "undetermined"
    t_open = None
    fall: DragArea | None = None
    if verdict == "opened" and previous is not None:
        t_open = rate_change_time(t, height, float(chute.deploy_time),  # type: ignore[arg-type]
                                  min(t_to, descent.t_from + HINGE_AFTER_S))
    late = None
    if verdict in ("opened", "partial") and previous is None:
        late = late_opening(t, height, density, mass,
                            float(chute.deploy_time), descent, t_to)  # type: ignore[arg-type]
    if late is not None:
        t_open, fall = (late[0], late[1]), late[3]
    why = _why(chute, verdict, descent, own, before, previous, cut, above, bound, t_open,
               already)
    if late is not None:
        why = (f"it took hold {late[0] - float(chute.deploy_time):.1f} s after its charge "  # type: ignore[arg-type]
               f"at {chute.deploy_time:.2f} s (hung in its bag, streaming or tangled?): the "
               f"fall before at {rounded(late[2], AIR_SIGMA_M_S)} m/s needs "
               f"{with_sigma(fall.value, fall.sigma)} m^2 (airframe and canopy); then {why}")  # type: ignore[union-attr]
    head = {"opened": f"the {name} opened"
            + (f" at {with_sigma(*t_open)} s" if t_open is not None else ""),
            "partial": f"the {name} opened only in part (a streamer, or a canopy partly "
                       "open or tangled?)",
            "not_opened": f"the {name} did not "
                          + ("open" if previous is None else "inflate"),
            "undetermined": f"the {name}: cannot tell whether it opened"}[verdict]
    return CanopyForensics(name, verdict, f"{head}: {why}", chute.deploy_time, descent, own,
                           before, cut, z_opened, None if z_opened is None else _p(z_opened),
                           z_short, None if z_short is None else _p(z_short), above,
                           None if t_open is None else t_open[0],
                           None if t_open is None else t_open[1], previous, fall)


def _why(chute: Canopy, verdict: str, descent: SettledDescent, own: DragArea,
         before: DragArea | None, previous: SettledDescent | None, cut: float | None,
         above: bool, bound: float | None, t_open: tuple[float, float] | None,
         already: bool) -> str:
    """The reason a verdict's sentence gives, with the numbers it rests on."""
    rate = f"{with_sigma(descent.rate, descent.rate_sigma)} m/s"
    needs = f"{with_sigma(descent.drag_area, descent.drag_area_sigma)} m^2"
    mine = f"{with_sigma(own.value, own.sigma)} m^2"
    diam = f"its {chute.diameter:.2f} m diameter" if chute.diameter else ""
    at_floor = ("" if cut is None else
                f"the {cut:.2g} m^2 {diam} gives at Cd {FLOOR_CD:g}, the least of an open "
                "canopy" if chute.diameter else
                f"the {cut:.2g} m^2 open before it (no diameter given: a canopy that does "
                "not double the drag area recovers nothing)")
    charge = f"its charge at {chute.deploy_time:.1f} s"
    stayed = f"the descent rate stayed {rate} across {charge}"
    if previous is not None:  # the rate before, in the air the descent after it flew in
        scale = math.sqrt(previous.density / descent.density)
        stayed += (f" ({with_sigma(previous.rate * scale, previous.rate_sigma * scale)} m/s "
                   "before, scaled to that air)")
    if verdict == "not_opened" and previous is not None and before is not None:
        return (f"{stayed}: it needs {needs} against {with_sigma(before.value, before.sigma)} "
                "m^2 before")
    if verdict == "not_opened" and before is not None:
        return (f"the descent at {rate} needs {needs}, the airframe's own drag area "
                f"({with_sigma(before.value, before.sigma)} m^2 from the {before.source}, with "
                f"a {AIRFRAME_MODEL_REL:.0%} allowance for its attitude)")
    if verdict == "not_opened":
        return (f"the descent at {rate} needs {needs}, far below {at_floor} (the drag area "
                "open before it is unknown: a streamer cannot be told from no canopy)")
    if verdict == "partial":
        return f"the descent at {rate} needs {needs}, its own {mine}, against {at_floor}"
    if verdict == "opened":
        cd = (f" (Cd {own.value / (math.pi * chute.diameter**2 / 4.0):.2g} on {diam})"
              if chute.diameter and before is not None else "")
        slowed = (f"the descent slowed from {rounded(previous.rate, previous.rate_sigma)} to "
                  f"{rate}" if previous is not None else f"the descent at {rate}")
        why = f"{slowed} needs {needs}, its own {mine}{cd}"
        if above:
            why += (f", more than {diam} can give ({bound:.2g} m^2 at Cd {MAX_CD:g}): a larger "
                    "canopy was out (the main, early?)")
        return why
    if already:
        return (f"{stayed}, but the descent before it needed more drag than the earlier "
                "canopies can give: it may have been out already")
    if descent.trend != "settled":
        bound_word = "at most" if descent.trend == "accelerating" else "at least"
        return (f"the descent was still {descent.trend} at {descent.t_to:.1f} s ({rate} "
                f"there needs {bound_word} {needs}): too short a settled descent to tell")
    if cut is None:
        return (f"the descent at {rate} needs {needs}: with no diameter and no drag area "
                "before it there is nothing to compare")
    return (f"the descent at {rate} needs {needs}; its own {mine} is within the noise of "
            + ("nothing and of " if before is not None else "") + at_floor)
