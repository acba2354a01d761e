"""Measurement models of the three basic sensor kinds.

* GPS: position (m, east-north-up from the test origin) and velocity (m/s)
  of the vehicle.
* IMU load factor: magnitude of the vehicle's specific force in g.
* Load cell: riser tension of one canopy (N) times its gain (load-cell scale,
  drag-scale and other sensor effects multiply ``loadcell_gain[P]``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..parameters import param_name
from .base import Effect

if TYPE_CHECKING:
    from ..model import ModelContext


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
