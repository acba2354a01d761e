"""Unit conversion at the boundary: everything inside the product is SI.

Each physical dimension has a table of accepted unit spellings and the factor
that turns a value in that unit into SI (m, kg, s, N, Pa, kg/m^3, m^2).
Temperatures are absolute (K) only: affine units such as degC are deliberately
absent, so every conversion stays one factor.
"""

from __future__ import annotations

import math

G0 = 9.80665  # standard gravity, m/s^2
FT = 0.3048  # m
LB = 0.45359237  # kg (pound mass)
LBF = LB * G0  # N (pound force)
SLUG = LBF / FT  # kg

FACTORS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3},
    "length": {"m": 1.0, "ft": FT, "km": 1e3, "in": FT / 12.0, "kft": 1e3 * FT},
    "velocity": {"m/s": 1.0, "ft/s": FT, "knots": 1852.0 / 3600.0, "kt": 1852.0 / 3600.0,
                 "km/h": 1.0 / 3.6},
    "mass": {"kg": 1.0, "lb": LB, "lbm": LB, "slug": SLUG},
    "force": {"N": 1.0, "kN": 1e3, "lbf": LBF, "klbf": 1e3 * LBF},
    "area": {"m^2": 1.0, "ft^2": FT**2},
    "density": {"kg/m^3": 1.0, "slug/ft^3": SLUG / FT**3},
    "acceleration": {"m/s^2": 1.0, "ft/s^2": FT, "g": G0},
    "load_factor": {"g": 1.0, "1": 1.0},
    "dimensionless": {"1": 1.0, "": 1.0},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
    "stiffness": {"N/m": 1.0, "lbf/ft": LBF / FT},
    "temperature": {"K": 1.0},
    "lapse_rate": {"K/m": 1.0, "K/km": 1e-3},
    "pressure": {"Pa": 1.0, "psf": LBF / FT**2, "hPa": 100.0, "kPa": 1e3,
                 "psi": LBF / (FT / 12) ** 2},
}

SI_UNIT = {dim: next(u for u, f in table.items() if f == 1.0) for dim, table in FACTORS.items()}


def known_units(dimension: str) -> list[str]:
    """Unit spellings accepted for a dimension."""
    return sorted(FACTORS[dimension])


def factor(unit: str, dimension: str) -> float:
    """SI factor of `unit` for `dimension`; KeyError if the unit is not of that dimension."""
    return FACTORS[dimension][unit]


def conversion(unit: str, si_unit: str) -> float | None:
    """The factor that turns a value in `unit` into one in `si_unit`, where both spell one
    dimension; None where they do not.  A dimensionless quantity (SI unit "1": a factor, a
    fill constant) takes only the dimensionless spellings: "g" also names a load factor, but
    a factor "fixed at 1 g" states an acceleration (9.81 m/s^2), a unit mistake, not 1.  A
    load factor (SI unit "g") takes "1" as well."""
    if unit == si_unit:
        return 1.0
    for dim, table in FACTORS.items():
        if dim == "load_factor" and si_unit in FACTORS["dimensionless"]:
            continue
        if unit in table and si_unit in table:
            return table[unit] / table[si_unit]
    return None


def dimension_of(unit: str, allowed: tuple[str, ...]) -> str | None:
    """The first of `allowed` dimensions that knows `unit`, or None."""
    for dim in allowed:
        if unit in FACTORS[dim]:
            return dim
    return None
