"""Atmosphere models: air density (and wind) as functions of altitude.

Every model returns CasADi expressions so the same code serves the estimator,
the simulator and the sensitivities; numeric evaluation goes through
`density_at`.  Altitude is geometric height above mean sea level in metres,
density is in kg/m^3, wind is the air-mass velocity (east, north) in m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .units import G0

R_AIR = 287.05287  # specific gas constant of dry air, J/(kg K)


@dataclass(frozen=True)
class StandardAtmosphere:
    """U.S. Standard Atmosphere 1976, troposphere and lower stratosphere (0-20 km).

    Troposphere: T = 288.15 K - 6.5 K/km * h, p = p0 (T/T0)^(g0/(R L)).
    Lower stratosphere (11-20 km): isothermal at 216.65 K, p decays exponentially.
    Geometric and geopotential height are not distinguished (< 0.3 % in
    density below 20 km), which is well below the spread of day-of-flight
    profiles; use a `TableAtmosphere` when a measured profile exists.
    """

    name: str = "standard"

    def density(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        t0, p0, lapse = 288.15, 101325.0, 0.0065
        h11 = 11000.0
        t_trop = t0 - lapse * ca.fmin(h, h11)
        p_trop = p0 * (t_trop / t0) ** (G0 / (R_AIR * lapse))
        p_strat = p_trop * ca.exp(-G0 / (R_AIR * 216.65) * ca.fmax(h - h11, 0.0))
        return p_strat / (R_AIR * t_trop)

    def wind(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        return ca.vertcat(0.0 * h, 0.0 * h, 0.0 * h)


@dataclass(frozen=True)
class TableAtmosphere:
    """Day-of-flight density (and optionally wind) profile from a table.

    Density is interpolated linearly in log(rho) between tabulated altitudes,
    which is exact for an isothermal layer; wind components linearly.  Outside
    the table the end values are extrapolated linearly (in log rho).
    """

    altitude_m: np.ndarray
    density_kg_m3: np.ndarray
    wind_east_m_s: np.ndarray | None = None
    wind_north_m_s: np.ndarray | None = None
    name: str = "table"
    _log_rho: ca.Function = field(init=False, repr=False, compare=False)
    _wind: ca.Function | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h = np.asarray(self.altitude_m, dtype=float)
        log_rho = np.log(np.asarray(self.density_kg_m3, dtype=float))
        object.__setattr__(self, "_log_rho", _linear_function("log_rho", h, log_rho))
        if self.wind_east_m_s is None or self.wind_north_m_s is None:
            object.__setattr__(self, "_wind", None)
        else:
            we = _linear_function("wind_e", h, np.asarray(self.wind_east_m_s, dtype=float))
            wn = _linear_function("wind_n", h, np.asarray(self.wind_north_m_s, dtype=float))
            hs = ca.SX.sym("h")
            object.__setattr__(
                self, "_wind", ca.Function("wind", [hs], [ca.vertcat(we(hs), wn(hs), 0.0)])
            )

    def density(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        return ca.exp(self._log_rho(h))

    def wind(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        if self._wind is None:
            return ca.vertcat(0.0 * h, 0.0 * h, 0.0 * h)
        return self._wind(h)


Atmosphere = StandardAtmosphere | TableAtmosphere


def _linear_function(name: str, x: np.ndarray, y: np.ndarray) -> ca.Function:
    """Piecewise-linear y(x) with linear extrapolation, as a CasADi SX Function.

    Written with `if_else` rather than a lookup so that it is differentiable to
    any order and inlines into SX graphs.
    """
    xs = ca.SX.sym("x")
    slopes = np.diff(y) / np.diff(x)
    expr = y[0] + slopes[0] * (xs - x[0])
    for k in range(1, len(x) - 1):
        expr = ca.if_else(xs >= x[k], y[k] + slopes[k] * (xs - x[k]), expr)
    return ca.Function(name, [xs], [expr])


def density_at(atmosphere: Atmosphere, h: np.ndarray | float) -> np.ndarray:
    """Numeric density (kg/m^3) at altitudes `h` (m)."""
    hs = ca.SX.sym("h")
    f = ca.Function("rho", [hs], [atmosphere.density(hs)])
    return np.asarray(f.map(np.size(h))(np.atleast_1d(h).reshape(1, -1))).ravel()


def wind_at(atmosphere: Atmosphere, h: np.ndarray | float) -> np.ndarray:
    """Numeric wind (m/s), shape (len(h), 3)."""
    hs = ca.SX.sym("h")
    f = ca.Function("wind", [hs], [atmosphere.wind(hs)])
    return np.asarray(f.map(np.size(h))(np.atleast_1d(h).reshape(1, -1))).T
