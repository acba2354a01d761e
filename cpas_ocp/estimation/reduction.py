"""Offline data reduction (paper Eqs. 2-3) and the initial guess it gives.

Without any simulation, on the IMU's time base:

* dynamic pressure q = rho(h) |v - w|^2 / 2 from the kinematic track (GPS
  position and velocity, or a vertical altimeter track; `kinematic_track`);
* IMU drag area, Eq. 2:      PRF*CdS_total = W_T G / q - (CdS)_V, with the load
  factor G from the IMU, or from the track's acceleration without one;
* riser drag area, Eq. 3:    PRF*CdS_P = (F_P + W_p,P G) / q;
* with neither load cells nor an IMU, a canopy's drag area is its share of the total drag
  area less the steady drag areas of the canopies opened before it (a
  rocket's drogue, then its main; a cluster shares equally);
* per-stage scale factor: the time mean of the IMU drag area over the
  stage's steady window divided by that of the summed riser drag areas
  (each times the cosine of its fly-out angle in a cluster, Eq. 7).  It
  is the initial guess of ``drag_scale[stage]``, since the trajectory's drag is
  the load-cell drag times that factor.

Clusters, their stages and the steady windows are those of `stage_groups`:
canopies whose first stages share a name and start together.

From these curves the initial guess of every canopy's inflation parameters
follows: CdS from the scaled riser drag area in the steady window, then the
start time and shape of every stage from a least-squares fit of the Eq. 5/6
curve to that drag area (`stage_curve_fit`).  The guess never uses anything
but the test folder.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.kinematic_track import kinematic_track
from cpas_ocp.estimation.stage_curve_fit import (
    MAX_WINDOW_S,
    StageData,
    fit_stage_curve,
    fitted_names,
)
from cpas_ocp.estimation.stage_groups import StageGroup, clusters, stage_groups
from cpas_ocp.io.flight_test import MANIFEST
from cpas_ocp.physics.atmosphere import density_at, wind_at
from cpas_ocp.physics.effects.canopy_inflation import steady_parameter_names
from cpas_ocp.physics.flight_test import FlightTest, Parachute
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name, split_name
from cpas_ocp.physics.units import G0


@dataclass
class Reduction:
    """Offline drag areas (m^2) on the time base `t` (s), with the track's altitude (m).

    `cds_riser` holds each canopy's drag area from its load cell (Eq. 3), or,
    in a test without load cells, attributed from the total drag area.  `groups`: every
    cluster's every stage with its steady window and scale factor (`stage_groups`).
    """

    t: np.ndarray
    altitude: np.ndarray
    dynamic_pressure: np.ndarray
    airspeed: np.ndarray
    load_factor: np.ndarray
    cds_imu: np.ndarray
    cds_riser: dict[str, np.ndarray]
    groups: list[StageGroup]

    def group_of(self, canopy: str, stage: str) -> StageGroup:
        """The group that starts `canopy`'s `stage`."""
        return next(g for g in self.groups if g.stage == stage and canopy in g.canopies)

    def drag_scale(self, stage: str) -> float:
        """Scale factor of the stages named `stage`, as the model's one ``drag_scale[stage]``
        takes it: the mean over the groups that start a stage so named (one in a cluster
        test)."""
        scales = [g.scale for g in self.groups if g.stage == stage]
        return sum(scales) / len(scales)


def reduce(test: FlightTest, starts: dict[tuple[str, str], float],
           flyout: dict[tuple[str, str], float] | None = None,
           forebody_cds: float | None = None) -> Reduction:
    """Offline reduction with stage start times `starts[(canopy, stage)]` (s).

    `flyout[(canopy, stage)]` (rad, default 0) are the fly-out angles of a
    cluster: the IMU drag area is matched to sum_i cos(theta_i) CdS_i (Eq. 7).
    `forebody_cds` (m^2) replaces the manifest's forebody drag area (a model
    that fixes ``CdS_V``).
    """
    flyout = flyout or {}
    imu = test.sensors_of("imu_load_factor")
    cells = test.sensors_of("load_cell")
    base = imu[0] if imu else (cells[0] if cells else test.sensors[0])
    t = base.time[(base.time >= test.t_start) & (base.time <= test.t_end)]
    track = kinematic_track(test, t)
    pos = track.position
    v_air = track.velocity - wind_at(test.atmosphere, pos[:, 2])
    airspeed = np.linalg.norm(v_air, axis=1)
    q = 0.5 * density_at(test.atmosphere, pos[:, 2]) * airspeed**2
    if imu:
        G = np.interp(t, imu[0].time, imu[0].data["load_factor"])
    else:  # specific force of the track: a - g, g pointing down
        G = np.linalg.norm(track.acceleration + np.array([0.0, 0.0, G0]), axis=1) / G0
    cds_imu = test.weight * G / q - (test.vehicle.forebody_cds if forebody_cds is None
                                 else forebody_cds)
    cds_riser = {}
    for cell in cells:
        chute = test.parachute(cell.parachute)
        tension = np.interp(t, cell.time, cell.data["tension"])
        cds_riser[chute.name] = (tension + chute.dry_mass * G0 * G) / q

    groups = stage_groups(test, starts)
    if not cells and not imu:  # an altimeter-only log: the track is all there is
        cds_riser = _attributed_cds(test, starts, groups, t, cds_imu)
    scaled = []
    for group in groups:
        a, b = group.window
        sel = (t >= a) & (t <= b)
        riser_sum = sum(np.cos(flyout.get((name, group.stage), 0.0)) * cds
                        for name, cds in cds_riser.items())
        if imu and cds_riser and sel.sum() > 3:
            group = replace(group, scale=float(np.mean(cds_imu[sel]) / np.mean(riser_sum[sel])))
        scaled.append(group)
    return Reduction(t, pos[:, 2], q, airspeed, G, cds_imu, cds_riser, scaled)


def _attributed_cds(test: FlightTest, starts: dict[tuple[str, str], float],
                    groups: list[StageGroup], t: np.ndarray,
                    cds_total: np.ndarray) -> dict[str, np.ndarray]:
    """Each canopy's drag area (m^2) without load cells.

    The canopies of a cluster (`stage_groups.clusters`: first stages of one name started
    together) share what is theirs equally; clusters opened later get the total drag
    area less the steady drag areas (medians over their last stage's steady window) of
    the clusters opened before them.
    """
    out: dict[str, np.ndarray] = {}
    opened = 0.0
    for cluster in clusters(test, starts):
        share = (cds_total - opened) / len(cluster)
        last = cluster[0].stages[-1]
        a, b = next(g.window for g in groups
                     if g.stage == last and cluster[0].name in g.canopies)
        steady = (t >= a) & (t <= b)
        for chute in cluster:
            out[chute.name] = share
        if steady.any():
            opened += len(cluster) * float(np.median(share[steady]))
    return out


def stage_starts(test: FlightTest, values: dict[str, float]) -> dict[tuple[str, str], float]:
    """Start time (s) of every canopy's every stage, keyed (canopy, stage), from `values`;
    the phase's start for a canopy open at it."""
    return {(c.name, s): test.t_start if c.open_at_start
            else values[param_name("t_start", c.name, s)]
            for c in test.parachutes for s in c.stages}


def initial_guess(test: FlightTest, model: Model,
                  fixed: dict[str, float] | None = None) -> dict[str, float]:
    """Initial values of the model parameters from the test folder alone (`fixed` held)."""
    return reduce_and_guess(test, model, fixed)[0]


def _fit_stage(test: FlightTest, red: Reduction, chute: Parachute, k: int,
               starts: dict[tuple[str, str], float], guess: dict[str, float],
               bounds: dict[str, tuple[float, float]], fixed: dict[str, float]
               ) -> dict[str, float] | None:
    """Curve-fitted shape and start of stage k of `chute` (`stage_curve_fit`), or None.

    The window runs from halfway back to the previous stage's observed start
    (at most 1 s before this one) to just before the next stage's, at most
    MAX_WINDOW_S after this one.
    """
    stage = chute.stages[k]
    t0 = starts[(chute.name, stage)]
    prev_start = starts[(chute.name, chute.stages[k - 1])] if k else test.t_start
    next_start = (starts[(chute.name, chute.stages[k + 1])] if k + 1 < len(chute.stages)
                  else test.t_end)
    lo = max(t0 - 1.0, prev_start + 0.5 * (t0 - prev_start))
    hi = min(t0 + MAX_WINDOW_S, next_start - 0.1)
    sel = (red.t >= lo) & (red.t <= hi)
    names = fitted_names(chute, stage)
    t_lo, t_hi = bounds[names[0]]
    fit_bounds = {**{n: bounds[n] for n in names}, names[0]: (max(t_lo, lo), min(t_hi, hi))}
    cds_of = [guess[param_name("CdS", chute.name, s)] for s in chute.stages]
    data = StageData(chute, stage, red.t[sel],
                     red.group_of(chute.name, stage).scale * red.cds_riser[chute.name][sel],
                     red.airspeed[sel], cds_of[k - 1] if k else 0.0, cds_of[k], cds_of[-1],
                     fit_bounds, {n: v for n, v in fixed.items() if n in names},
                     red.dynamic_pressure[sel])
    return fit_stage_curve(data)


def _steady_names(test: FlightTest, red: Reduction, chute: Parachute, stage: str,
                  steady: np.ndarray) -> list[tuple[str, tuple[float, float]]]:
    """Each steady drag-area parameter of `chute`'s `stage` with the altitudes (m) it covers:
    one per altitude band of a canopy open at the start (`steady_parameter_names`), else
    the stage's CdS over all altitudes."""
    if chute.open_at_start:
        return [(name, chute.band_range(split_name(name)[1][-1]) if chute.band_names
                 else (-np.inf, np.inf)) for name in steady_parameter_names(chute)]
    return [(param_name("CdS", chute.name, stage), (-np.inf, np.inf))]


def _require_bands_entered(test: FlightTest, red: Reduction, chute: Parachute) -> None:
    """InputError naming the manifest's altitude bands of `chute` where the phase's
    altitude track (m MSL) never enters one of them: no data would determine its drag
    area, and the fit would report the guess as an estimate."""
    for band in chute.band_names:
        lo, hi = chute.band_range(band)
        if not ((red.altitude >= lo) & (red.altitude < hi)).any():
            i = [c.name for c in test.parachutes].index(chute.name)
            raise InputError(str((test.path or Path()) / MANIFEST),
                             f"parachutes[{i}].altitude_bands",
                             f"edges the descent crosses; {band} ({lo:.0f} to {hi:.0f} m) lies "
                             f"outside the altitudes of the phase ({red.altitude.min():.0f} to "
                             f"{red.altitude.max():.0f} m MSL)")


def reduce_and_guess(test: FlightTest, model: Model, fixed: dict[str, float] | None = None
                     ) -> tuple[dict[str, float], Reduction]:
    """The initial guess and the reduction it came from (start times from the events).

    Parameters in `fixed` keep their values, and the curve fits hold them.
    """
    fixed = dict(fixed or {})
    guess = {p.name: p.default for p in model.parameters} | fixed
    starts = stage_starts(test, guess)
    flyout = {(c.name, s): guess[param_name("flyout_angle", c.name, s)]
              for c in test.parachutes for s in c.stages
              if param_name("flyout_angle", c.name, s) in guess}
    red = reduce(test, starts, flyout, guess.get("CdS_V"))
    bounds = {p.name: (p.lower, p.upper) for p in model.parameters}
    for stage in dict.fromkeys(g.stage for g in red.groups):
        name = param_name("drag_scale", stage)
        if name in guess and name not in fixed:
            guess[name] = float(np.clip(red.drag_scale(stage), *bounds[name]))
    for chute in test.parachutes:
        _require_bands_entered(test, red, chute)
        curve = red.cds_riser.get(chute.name)
        if curve is None:
            continue
        for stage in chute.stages:
            group = red.group_of(chute.name, stage)
            a, b = group.window
            steady = (red.t >= a) & (red.t <= b)
            # The riser sees PRF*CdS (wake_deficit); the model's CdS is the free-stream one.
            prf = guess.get(param_name("prf", chute.name), 1.0)
            for name, (lo, hi) in _steady_names(test, red, chute, stage, steady):
                sel = steady & (red.altitude >= lo) & (red.altitude < hi)
                cds = group.scale * float(np.median(curve[sel])) \
                    if sel.any() else 0.0
                if cds > 0 and name not in fixed:
                    guess[name] = cds / prf
        if chute.open_at_start:
            continue  # no opening: nothing to fit but the steady drag areas
        for k in range(len(chute.stages)):
            shape = _fit_stage(test, red, chute, k, starts, guess, bounds, fixed)
            if shape is not None:
                guess.update(shape)
    return guess, red
