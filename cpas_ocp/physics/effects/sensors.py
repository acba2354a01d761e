"""Measurement models of the basic sensor kinds.

* GPS: position (m, east-north-up from the test origin) and velocity (m/s)
  of the vehicle.
* IMU load factor: magnitude of the vehicle's specific force in g.
* Load cell: riser tension of one canopy (N) times its gain (load-cell scale,
  drag-scale and other sensor effects multiply ``loadcell_gain[P]``).
* Barometric altimeter: the pressure altitude (m) of the air pressure at the
  vehicle, i.e. the standard-atmosphere altitude of the test atmosphere's
  pressure there.  Flight computers report this as "altitude".
* GPS altitude: geometric altitude above mean sea level (m), for receivers
  whose log holds no velocity.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from cpas_ocp.errors import InputError
from cpas_ocp.physics.atmosphere import pressure_altitude
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.model_context import ModelContext


@dataclass(frozen=True)
class GpsSensor(Effect):
    """GPS: the vehicle's position (m, east-north-up) and velocity (m/s)."""

    name: str = "gps"

    def observations(self, ctx: ModelContext) -> None:
        r, v = ctx.x["position"], ctx.x["velocity"]
        for s in ctx.test.sensors_of("gps"):
            ctx.y[s.name] = {"east": r[0], "north": r[1], "up": r[2],
                             "v_east": v[0], "v_north": v[1], "v_up": v[2]}


@dataclass(frozen=True)
class ImuSensor(Effect):
    """IMU: load factor |f| / g0 of the vehicle's specific force (g)."""

    name: str = "imu"

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of("imu_load_factor"):
            ctx.y[s.name] = {"load_factor": ctx.q["load_factor"]}


@dataclass(frozen=True)
class LoadCellSensor(Effect):
    """Riser load cell: the canopy's riser tension times its load-cell gain (N)."""

    name: str = "load_cell"

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of("load_cell"):
            gain = ctx.q.get(param_name("loadcell_gain", s.parachute), 1.0)
            ctx.y[s.name] = {"tension": gain * ctx.q[param_name("tension", s.parachute)]}


@dataclass(frozen=True)
class BaroSensor(Effect):
    """Barometric altimeter: pressure altitude (m) of the test atmosphere's pressure at the vehicle.

    On a standard day this is the geometric altitude; on a hot day the pressure
    falls more slowly with height and the altimeter under-reads the height
    gained (by about a tenth at 30 K above standard: near sea level it reads
    906 m for 1,000 m climbed).
    """

    name: str = "baro"

    def observations(self, ctx: ModelContext) -> None:
        sensors = ctx.test.sensors_of("baro")
        if not sensors:
            return
        atm = ctx.test.atmosphere
        if not hasattr(atm, "pressure"):
            raise InputError(str(ctx.test.path or "manifest"), "atmosphere.model",
                             "'standard', 'site', or a table with a temperature or "
                             "pressure column, for a barometric altimeter (a density table "
                             "has no pressure)")
        h_p = pressure_altitude(atm.pressure(ctx.x["position"][2]))
        for s in sensors:
            ctx.y[s.name] = {"altitude": h_p}


@dataclass(frozen=True)
class GpsAltitudeSensor(Effect):
    """GPS altitude: geometric altitude of the vehicle above mean sea level (m)."""

    name: str = "gps_altitude"

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of("gps_altitude"):
            ctx.y[s.name] = {"up": ctx.x["position"][2]}
