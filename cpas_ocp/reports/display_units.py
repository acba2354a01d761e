"""The units figures and tables are drawn in: SI or US customary, chosen per test.

Everything inside the product (and result.json) is SI.  A report shows lengths, speeds,
forces, areas and masses in the system the test's manifest is written in, unless the
command line says otherwise (``--units si|us``).  The manifest's system is read from
its dimensional quantities (every ``{value, unit}`` object and every sensor column's
unit): the system with more of them wins, SI on a tie.  Units common to both (s, g, K,
deg, dimensionless) count for neither.  The conversion factors are those of
`cpas_ocp.physics.units`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cpas_ocp.physics.units import FACTORS, SI_UNIT

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest

SYSTEMS = ("si", "us")

# Units that mark a manifest as written in US customary or in SI units.
US_CUSTOMARY = frozenset({"ft", "in", "kft", "ft/s", "lb", "lbm", "slug", "lbf", "klbf",
                          "ft^2", "slug/ft^3", "ft/s^2", "lbf/ft", "psf", "psi"})
SI_FAMILY = frozenset({"m", "km", "m/s", "km/h", "kg", "N", "kN", "m^2", "kg/m^3", "m/s^2",
                       "N/m", "Pa", "hPa", "kPa", "K/m", "K/km"})

# The US customary display unit of each dimension that has one (others stay SI).
US_DISPLAY = {"length": "ft", "velocity": "ft/s", "mass": "lb", "force": "lbf",
              "area": "ft^2", "density": "slug/ft^3", "acceleration": "ft/s^2",
              "stiffness": "lbf/ft", "pressure": "psf"}

# The physical dimension of each sensor channel (its model value is SI).
CHANNEL_DIMENSION = {"east": "length", "north": "length", "up": "length",
                     "altitude": "length", "v_east": "velocity", "v_north": "velocity",
                     "v_up": "velocity", "tension": "force", "acceleration": "acceleration",
                     "load_factor": "load_factor"}

# Dimensions by their SI unit, to convert a parameter whose unit is stated in SI.
DIMENSION_OF_SI = {unit: dim for dim, unit in SI_UNIT.items()
                   if dim not in ("load_factor", "dimensionless")}


@dataclass(frozen=True)
class DisplayUnits:
    """A unit system for display: ``si`` or ``us`` (US customary)."""

    system: str

    def __post_init__(self) -> None:
        if self.system not in SYSTEMS:
            raise ValueError(f"a unit system is one of {SYSTEMS}; got {self.system!r}")

    def unit(self, dimension: str) -> str:
        """The display unit of a dimension (a `physics.units.FACTORS` key)."""
        if self.system == "us" and dimension in US_DISPLAY:
            return US_DISPLAY[dimension]
        return SI_UNIT[dimension]

    def factor(self, dimension: str) -> float:
        """What an SI value of `dimension` is multiplied by to read in the display unit."""
        return 1.0 / FACTORS[dimension][self.unit(dimension)]

    def channel(self, channel: str) -> tuple[str, float]:
        """A sensor channel's display unit and the factor from SI ("SI", 1 if unknown)."""
        dim = CHANNEL_DIMENSION.get(channel)
        return ("SI", 1.0) if dim is None else (self.unit(dim), self.factor(dim))

    def of_si(self, si_unit: str) -> tuple[str, float]:
        """The display unit of a quantity stated in the SI unit `si_unit` (a parameter's),
        and the factor from SI; a unit of no convertible dimension is kept (factor 1)."""
        dim = DIMENSION_OF_SI.get(si_unit)
        return (si_unit, 1.0) if dim is None else (self.unit(dim), self.factor(dim))


def pretty(unit: str) -> str:
    """A unit for a label: ``ft^2`` as ``ft²``, ``kg/m^3`` as ``kg/m³``."""
    return unit.replace("^2", "²").replace("^3", "³")


def _units_in(node: Any) -> Iterator[str]:
    """Every unit a manifest states: of its {value, unit} objects and its column maps."""
    if isinstance(node, dict):
        if "unit" in node and "value" in node and isinstance(node["unit"], str):
            yield node["unit"]
        for key, value in node.items():
            if key == "columns" and isinstance(value, dict):
                yield from (u for u in value.values() if isinstance(u, str))
            else:
                yield from _units_in(value)
    elif isinstance(node, list):
        for item in node:
            yield from _units_in(item)


def manifest_system(manifest: dict[str, Any]) -> str:
    """The unit system a manifest is written in: ``us`` where more of its dimensional
    quantities are in US customary units than in SI ones, else ``si``."""
    units = list(_units_in(manifest))
    us = sum(u in US_CUSTOMARY for u in units)
    si = sum(u in SI_FAMILY for u in units)
    return "us" if us > si else "si"


def display_units(test: FlightTest, choice: str | None = None) -> DisplayUnits:
    """The display units of a test's reports: `choice` (``si``/``us``) where given, else
    the system its manifest is written in (SI for a test built without one)."""
    return DisplayUnits(choice if choice is not None else manifest_system(test.manifest))
