"""The vehicle's kinematic track from the data alone, before any model is fitted.

The offline reduction and the estimator's starting point need position,
velocity and acceleration on a time base.  With GPS they are the GPS
position and velocity.  Without GPS (hobby-rocket logs) the motion is taken
as vertical and the altitude comes from the barometric altimeter, turned
from pressure altitude into geometric altitude through the test atmosphere
(`atmosphere.geometric_altitude`), or else from a GPS altitude channel.  The
altitude is resampled to a uniform grid and smoothed by a Savitzky-Golay
filter (local quadratic least squares), whose first and second derivatives
give the vertical velocity and acceleration.  The window, `SMOOTH_S`, is
long against the altimeter's sampling (about 0.1 s) and short against the
descent's time scales (a steady descent changes speed over tens of seconds;
an opening shock over about one second, which the smoothed track blurs:
it is a starting point, not a result).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import MANIFEST
from cpas_ocp.physics.atmosphere import geometric_altitude
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model

SMOOTH_S = 5.0  # Savitzky-Golay window of the vertical track (s)
RESAMPLE_S = 0.05  # uniform grid the altitude is resampled to before smoothing (s)


@dataclass(frozen=True)
class Track:
    """Position (m, ENU), velocity (m/s) and acceleration (m/s^2) at times `t` (s), shape (n, 3)."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


def kinematic_track(test: FlightTest, t: np.ndarray) -> Track:
    """The track at times `t` (s): GPS where the test has it, else the vertical altimeter track."""
    gps = test.sensors_of("gps")
    if gps:
        d = gps[0].data
        pos = np.column_stack([np.interp(t, d["time"], d[c]) for c in ("east", "north", "up")])
        vel = np.column_stack([np.interp(t, d["time"], d[c])
                               for c in ("v_east", "v_north", "v_up")])
        acc = np.column_stack([np.gradient(vel[:, i], t) if len(t) > 1 else np.zeros(len(t))
                               for i in range(3)])
        return Track(t, pos, vel, acc)
    return _vertical_track(test, t)


def altimeter_altitude(test: FlightTest) -> tuple[np.ndarray, np.ndarray]:
    """Sample times (s) and geometric altitude (m) of the test's altimeter: the barometric
    one through the test atmosphere, else a GPS altitude channel."""
    baro = test.sensors_of("baro")
    if baro:
        return baro[0].time, geometric_altitude(test.atmosphere,
                                                baro[0].data["altitude"].to_numpy())
    gps_alt = test.sensors_of("gps_altitude")
    if gps_alt:
        return gps_alt[0].time, gps_alt[0].data["up"].to_numpy()
    raise InputError(str(test.path / MANIFEST) if test.path is not None else test.name,
                     "sensors", "a GPS, barometric or GPS-altitude sensor (the kinematic track "
                     "needs the vehicle's position)")


def _vertical_track(test: FlightTest, t: np.ndarray) -> Track:
    ts, h = altimeter_altitude(test)
    grid = np.arange(ts[0], ts[-1] + 0.5 * RESAMPLE_S, RESAMPLE_S)
    hg = np.interp(grid, ts, h)
    window = min(2 * (int(SMOOTH_S / RESAMPLE_S) // 2) + 1, len(grid) - (1 - len(grid) % 2))
    if window < 5:
        raise ValueError(f"{test.name}: too few altimeter samples for a track")
    smooth = savgol_filter(hg, window, 2)
    rate = savgol_filter(hg, window, 2, deriv=1, delta=RESAMPLE_S)
    accel = savgol_filter(hg, window, 2, deriv=2, delta=RESAMPLE_S)
    zeros = np.zeros(len(t))
    return Track(t, np.column_stack([zeros, zeros, np.interp(t, grid, smooth)]),
                 np.column_stack([zeros, zeros, np.interp(t, grid, rate)]),
                 np.column_stack([zeros, zeros, np.interp(t, grid, accel)]))


def guessed_states(test: FlightTest, model: Model, values: dict[str, float], t: np.ndarray
                   ) -> tuple[np.ndarray, set[str]]:
    """States at times `t` (s; nx x len(t), SI) from the kinematic track and the effects' own
    guesses from the data (`Effect.state_guess`, at the parameter `values`), pinned states
    at their start values, and the names of the states so guessed (the others are zero)."""
    track = kinematic_track(test, t)
    x0 = np.zeros((model.nx, len(t)))
    x0[model.state_slice("position")] = track.position.T
    x0[model.state_slice("velocity")] = track.velocity.T
    guessed = {"position", "velocity"}
    for name, value in effect_state_guesses(test, model, values, t).items():
        x0[model.state_slice(name)] = value
        guessed.add(name)
    for st in model.states:
        if st.pinned:
            x0[model.state_slice(st.name), 0] = st.initial
    return x0, guessed


def effect_state_guesses(test: FlightTest, model: Model, values: dict[str, float],
                         t: np.ndarray) -> dict[str, np.ndarray]:
    """The effects' own guesses of their states at times `t` (`Effect.state_guess`)."""
    out: dict[str, np.ndarray] = {}
    for effect in model.effects:
        out.update(effect.state_guess(test, t, values))
    return out
