"""Fairlead friction: a load cell reads low while the riser tension rises, high while it falls.

The paper's load cells sit inside the vehicle, below the fairlead the
risers bend over (Section IV).  Friction on the fairlead opposes the riser's
motion: while the canopy pulls harder the riser creeps outward and the cell
sees less than the canopy's pull; while the pull eases it creeps back and the
cell sees more.  A steady loss is the stage's drag scale factor
(`drag_scale`); this effect adds the part that follows the load's rate:

    reading = T (1 - phi tanh(tau dT/dt / (|T| + T_0)))

with ``friction_loss[P]`` = phi (the fraction lost in a fast rise, estimable,
default 0; negative values are allowed so that "no friction" is an interior
point), tau = `response_s` (0.1 s: a rise of 5.5 T per second, a Drogue's
fill, carries the friction halfway to its full value; a Main's fill, under
1 T per second, about a tenth of the way) and T_0 = 1 kN keeping the ratio
finite before the riser loads.  dT/dt is a central difference over RATE_WINDOW_S
(40 ms) along the trajectory, like the added-mass rate, so the reading stays
continuous in the parameters that move the corners of the Eq. 5/6 curve.
List it after the load-cell sensor.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.added_mass import RATE_WINDOW_S
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

TENSION_FLOOR_N = 1000.0
MAX_FRICTION = 0.5


@dataclass(frozen=True)
class LoadCellFriction(Effect):
    """Rate-dependent fairlead friction on every load cell, ``friction_loss[P]``."""

    response_s: float = 0.1
    name: str = "loadcell_friction"

    def __post_init__(self) -> None:
        if not self.response_s > 0.0:
            raise ValueError(f"response_s must be positive; got {self.response_s}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("friction_loss", s.parachute), "1", 0.0, -MAX_FRICTION,
                          MAX_FRICTION, description="load lost to fairlead friction in a fast "
                          "rise", scale=0.05)
                for s in test.sensors_of("load_cell")]

    def plausible(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """Friction opposes the riser's motion through the fairlead: in a rise the load
        cell reads less than the tension (phi >= 0).  The estimate may take either sign (so
        that no friction is an interior point); a negative one marks a stand-in."""
        return {param_name("friction_loss", s.parachute): (0.0, MAX_FRICTION)
                for s in test.sensors_of("load_cell")}

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No friction: phi = 0 (inside the bounds; either sign is an alternative)."""
        return {param_name("friction_loss", s.parachute): 0.0
                for s in test.sensors_of("load_cell")}

    def observations(self, ctx: ModelContext) -> None:
        half = 0.5 * RATE_WINDOW_S
        for s in ctx.test.sensors_of("load_cell"):
            if s.name not in ctx.y:
                raise ValueError("list the loadcell_friction effect after the load_cell sensor")
            tension = ctx.q[param_name("tension", s.parachute)]
            rate = (ctx.at_time_offset(tension, half, 1)
                    - ctx.at_time_offset(tension, -half, 1)) / RATE_WINDOW_S
            phi = ctx.p[param_name("friction_loss", s.parachute)]
            relative = self.response_s * rate / (ca.fabs(tension) + TENSION_FLOOR_N)
            ctx.y[s.name]["tension"] = ctx.y[s.name]["tension"] * (1.0 - phi * ca.tanh(relative))
