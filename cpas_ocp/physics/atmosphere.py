"""Atmosphere models: air density (and wind) as functions of altitude.

Every model returns CasADi expressions so the same code serves the estimator,
the simulator and the sensitivities; numeric evaluation goes through
`density_at`.  Altitude is geometric height above mean sea level in metres,
density is in kg/m^3, pressure in Pa, wind is the air-mass velocity (east,
north) in m/s.

A barometric altimeter reports the *pressure altitude*: the altitude at which
the standard atmosphere has the measured pressure (`pressure_altitude`).  On a
day that is not standard it differs from the geometric altitude by tens to
hundreds of metres; a `SiteAtmosphere` built from the launch-site pressure and
temperature, or a `SoundingAtmosphere` from a day-of-flight sounding, turns one
into the other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from cpas_ocp.physics.units import G0

R_AIR = 287.05287  # specific gas constant of dry air, J/(kg K)
# U.S. Standard Atmosphere 1976 at sea level and its tropospheric lapse rate.
ISA_T0_K = 288.15
ISA_P0_PA = 101325.0
ISA_LAPSE_K_M = 0.0065
ISA_TROPOPAUSE_K = 216.65  # the standard atmosphere's isothermal lower stratosphere


def pressure_altitude(p: ca.SX | ca.MX | float | np.ndarray) -> ca.SX | ca.MX | np.ndarray:
    """Altitude (m) at which the standard troposphere has pressure `p` (Pa).

    h = T0/L (1 - (p/p0)^(R L/g0)); what barometric altimeters (Altus Metrum
    among them) report as altitude.  Valid below 11 km.
    """
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (p / ISA_P0_PA) ** (R_AIR * ISA_LAPSE_K_M / G0))


def _troposphere_pressure(h: ca.SX | ca.MX | float, h0: float, p0: float, t0: float,
                          lapse: float) -> ca.SX | ca.MX:
    """Hydrostatic pressure (Pa) at altitude h (m) in a layer of constant lapse rate (K/m)
    whose base h0 has pressure p0 (Pa) and temperature t0 (K)."""
    return p0 * ((t0 - lapse * (h - h0)) / t0) ** (G0 / (R_AIR * lapse))


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

    def pressure(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        h11 = 11000.0
        p_trop = _troposphere_pressure(ca.fmin(h, h11), 0.0, ISA_P0_PA, ISA_T0_K, ISA_LAPSE_K_M)
        return p_trop * ca.exp(-G0 / (R_AIR * ISA_TROPOPAUSE_K) * ca.fmax(h - h11, 0.0))

    def altitude_at_pressure(self, p: np.ndarray | float) -> np.ndarray:
        """Altitude (m) at pressure `p` (Pa): the pressure altitude (troposphere only)."""
        return np.asarray(pressure_altitude(np.asarray(p, dtype=float)))

    def density(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        t_trop = ISA_T0_K - ISA_LAPSE_K_M * ca.fmin(h, 11000.0)
        return self.pressure(h) / (R_AIR * t_trop)

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


def hydrostatic_pressure(altitude_m: np.ndarray, temperature_k: np.ndarray,
                         base_pressure_pa: float) -> np.ndarray:
    """Pressure (Pa) at the rows of a temperature profile, integrated hydrostatically
    upward from `base_pressure_pa` at its first row: dp/dh = -p g0 / (R T).

    Temperature is taken linear in altitude between rows, for which each layer
    integrates exactly: p2 = p1 (T2/T1)^(g0/(R L)) with lapse rate L = -(T2 - T1)/(h2 - h1),
    or p2 = p1 exp(-g0 (h2 - h1) / (R T)) in an isothermal layer (|L| below 1e-9 K/m)."""
    h = np.asarray(altitude_m, dtype=float)
    temp = np.asarray(temperature_k, dtype=float)
    p = np.empty_like(h)
    p[0] = base_pressure_pa
    for k in range(1, h.size):
        dh = h[k] - h[k - 1]
        lapse = -(temp[k] - temp[k - 1]) / dh
        if abs(lapse) < 1e-9:
            p[k] = p[k - 1] * np.exp(-G0 * dh / (R_AIR * temp[k - 1]))
        else:
            p[k] = float(_troposphere_pressure(h[k], h[k - 1], p[k - 1], temp[k - 1], lapse))
    return p


def _extrapolated_interp(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Numeric piecewise-linear fp(xp) at x with the end segments extended (xp increasing):
    what `_linear_function` evaluates, in numpy."""
    x = np.asarray(x, dtype=float)
    out = np.interp(x, xp, fp)
    lo, hi = x < xp[0], x > xp[-1]
    out[lo] = fp[0] + (x[lo] - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0])
    out[hi] = fp[-1] + (x[hi] - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
    return out


@dataclass(frozen=True)
class SoundingAtmosphere:
    """Day-of-flight profile with pressure: a sounding or reanalysis table.

    Rows of altitude (m), pressure (Pa), temperature (K), density (kg/m^3) and
    optionally wind (m/s).  Pressure is interpolated linearly in log(p) between
    rows (exact in an isothermal layer; within (dh)^2 g0 L / (8 R T^2) of the
    hydrostatic value in a layer of lapse rate L), density in log(rho) and wind
    linearly (`TableAtmosphere`), the end segments extended beyond the table.
    `from_profile` fills in what a sounding leaves out: pressure by hydrostatic
    integration of the temperature, density from the gas law rho = p / (R T).
    With pressure it serves a barometric altimeter.
    """

    altitude_m: np.ndarray
    pressure_pa: np.ndarray
    temperature_k: np.ndarray
    density_kg_m3: np.ndarray
    wind_east_m_s: np.ndarray | None = None
    wind_north_m_s: np.ndarray | None = None
    name: str = "table"
    _table: TableAtmosphere = field(init=False, repr=False, compare=False)
    _log_p: ca.Function = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_table", TableAtmosphere(
            self.altitude_m, self.density_kg_m3, self.wind_east_m_s, self.wind_north_m_s))
        object.__setattr__(self, "_log_p", _linear_function(
            "log_p", np.asarray(self.altitude_m, dtype=float),
            np.log(np.asarray(self.pressure_pa, dtype=float))))

    @classmethod
    def from_profile(cls, altitude_m: np.ndarray, *, temperature_k: np.ndarray | None = None,
                     pressure_pa: np.ndarray | None = None,
                     density_kg_m3: np.ndarray | None = None,
                     base_pressure_pa: float | None = None,
                     wind_east_m_s: np.ndarray | None = None,
                     wind_north_m_s: np.ndarray | None = None) -> SoundingAtmosphere:
        """The profile from what a sounding gives, the rest by the gas law and hydrostatics.

        Two of pressure, temperature and density give the third (p = rho R T).
        Temperature alone gives pressure by `hydrostatic_pressure` from
        `base_pressure_pa` at the first row (the standard atmosphere's pressure
        there when not given), then density.  ValueError where too little is given.
        """
        h = np.asarray(altitude_m, dtype=float)
        if pressure_pa is None and temperature_k is not None:
            base = (float(StandardAtmosphere().pressure(h[0])) if base_pressure_pa is None
                    else base_pressure_pa)
            pressure_pa = hydrostatic_pressure(h, temperature_k, base)
        if pressure_pa is None:
            raise ValueError("a temperature or pressure profile (pressure needs one of them)")
        p = np.asarray(pressure_pa, dtype=float)
        if temperature_k is None and density_kg_m3 is None:
            raise ValueError("a temperature or density profile beside the pressure")
        temp = (p / (R_AIR * np.asarray(density_kg_m3, dtype=float)) if temperature_k is None
                else np.asarray(temperature_k, dtype=float))
        rho = p / (R_AIR * temp) if density_kg_m3 is None else np.asarray(density_kg_m3,
                                                                          dtype=float)
        return cls(h, p, temp, rho, wind_east_m_s, wind_north_m_s)

    def pressure(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        """Pressure (Pa) at geometric altitude `h` (m): log(p) linear between rows."""
        return ca.exp(self._log_p(h))

    def density(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        """Density (kg/m^3) at `h` (m): log(rho) linear between rows."""
        return self._table.density(h)

    def wind(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        """Wind velocity (east, north, up = 0) (m/s) at `h` (m), linear between rows; zero
        where the table has no wind."""
        return self._table.wind(h)

    def altitude_at_pressure(self, p: np.ndarray | float) -> np.ndarray:
        """Geometric altitude (m) at pressure `p` (Pa): the inverse of `pressure`, linear in
        log(p) between rows and beyond them."""
        log_p = np.log(np.asarray(self.pressure_pa, dtype=float))
        return _extrapolated_interp(-np.log(np.atleast_1d(np.asarray(p, dtype=float))),
                                    -log_p, np.asarray(self.altitude_m, dtype=float)
                                    ).reshape(np.shape(p))


@dataclass(frozen=True)
class SiteAtmosphere:
    """Launch-site atmosphere: one tropospheric layer through the site's measured air.

    At the site elevation h0 (m) the pressure is p0 (Pa) and the temperature
    T0 (K); temperature falls at `lapse_rate` (K/m) with height, and pressure
    and density follow hydrostatically:
    T = T0 - L (h - h0), p = p0 (T/T0)^(g0/(R L)), rho = p/(R T).
    A sunny desert afternoon has lapse rates between the standard 6.5 K/km and
    the dry adiabat's 9.8 K/km.  Above its tropopause, where T falls to the
    standard's 216.65 K (11 km for the standard's air), the air is isothermal as
    the standard's lower stratosphere: p = p_t exp(-g0 (h - h_t) / (R T_t)), so
    that a height a solver's iterate wanders to reads finite air (the linear
    temperature alone reaches zero 44 km above a 288 K site at 6.5 K/km, and
    its pressure and density are NaN beyond).  No wind.
    """

    elevation_m: float
    pressure_pa: float
    temperature_k: float
    lapse_rate_k_m: float = ISA_LAPSE_K_M
    name: str = "site"

    @property
    def tropopause_m(self) -> float:
        """Height (m) where the temperature falls to ISA_TROPOPAUSE_K (the site's elevation
        where its air is colder)."""
        return self.elevation_m + max(self.temperature_k - ISA_TROPOPAUSE_K, 0.0) \
            / self.lapse_rate_k_m

    def _below_tropopause(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX | np.ndarray:
        if isinstance(h, ca.SX | ca.MX | ca.DM):
            return ca.fmin(h, self.tropopause_m)
        return np.minimum(h, self.tropopause_m)

    def temperature(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        return self.temperature_k - self.lapse_rate_k_m * (self._below_tropopause(h)
                                                           - self.elevation_m)

    def pressure(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        below = self._below_tropopause(h)
        p_trop = _troposphere_pressure(below, self.elevation_m, self.pressure_pa,
                                       self.temperature_k, self.lapse_rate_k_m)
        # Isothermal above the tropopause: exp(-(h - h_t) g0 / (R T_t)); 1 below it.
        scale = -G0 / (R_AIR * min(self.temperature_k, ISA_TROPOPAUSE_K))
        exp = ca.exp if isinstance(h, ca.SX | ca.MX | ca.DM) else np.exp
        return p_trop * exp(scale * (h - below))

    def density(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        return self.pressure(h) / (R_AIR * self.temperature(h))

    def wind(self, h: ca.SX | ca.MX | float) -> ca.SX | ca.MX:
        return ca.vertcat(0.0 * h, 0.0 * h, 0.0 * h)

    def altitude_at_pressure(self, p: np.ndarray | float) -> np.ndarray:
        """Geometric altitude (m) at which this atmosphere has pressure `p` (Pa)."""
        expo = R_AIR * self.lapse_rate_k_m / G0
        p = np.asarray(p, dtype=float)
        h_t = self.tropopause_m
        p_t = float(_troposphere_pressure(h_t, self.elevation_m, self.pressure_pa,
                                          self.temperature_k, self.lapse_rate_k_m))
        t_t = min(self.temperature_k, ISA_TROPOPAUSE_K)
        below = self.elevation_m + self.temperature_k / self.lapse_rate_k_m * (
            1.0 - (np.maximum(p, p_t) / self.pressure_pa) ** expo)
        return np.where(p >= p_t, below, h_t + R_AIR * t_t / G0 * np.log(p_t / p))

    @classmethod
    def from_surface_density(cls, elevation_m: float, pressure_pa: float, density_kg_m3: float,
                             lapse_rate_k_m: float = ISA_LAPSE_K_M) -> SiteAtmosphere:
        """The site atmosphere whose surface air has this pressure and density (T = p/(R rho))."""
        return cls(elevation_m, pressure_pa, pressure_pa / (R_AIR * density_kg_m3),
                   lapse_rate_k_m)


Atmosphere = StandardAtmosphere | TableAtmosphere | SiteAtmosphere | SoundingAtmosphere


def geometric_altitude(atmosphere: Atmosphere, p_altitude: np.ndarray) -> np.ndarray:
    """Geometric altitude (m) from a barometric altimeter's pressure altitude (m)."""
    p = ISA_P0_PA * (1.0 - np.asarray(p_altitude) * ISA_LAPSE_K_M / ISA_T0_K) ** (
        G0 / (R_AIR * ISA_LAPSE_K_M))
    invert = getattr(atmosphere, "altitude_at_pressure", None)
    if invert is None:
        raise TypeError("a barometric altitude needs an atmosphere with pressure (standard, site, "
                        "or a table with pressure or temperature)")
    return invert(p)


def _linear_function(name: str, x: np.ndarray, y: np.ndarray) -> ca.Function:
    """Piecewise-linear y(x) with linear extrapolation, as a CasADi Function.

    A lookup (CasADi's linear interpolant, a call node in SX graphs, with its
    derivatives and generated code): its cost is one binary search, whatever
    the table's length.  Written as a chain of `if_else` branches, each row
    cost a branch in every density and wind evaluation of the model (four per
    RK4 step), and a 111-row sounding exhausted the compiler's memory.
    """
    return ca.interpolant(name, "linear", [np.asarray(x, dtype=float)],
                          np.asarray(y, dtype=float))


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
