"""Inelastic deployment load of mortar-deployed canopies (FBCPs, Drogues; paper Sec. III).

While a canopy's risers and suspension lines leave its bag they are
re-accelerated to the vehicle's speed, which slows the vehicle.  The paper's
simulation models this as an "inelastic load": a constant extra drag on the
vehicle, acting through the canopy, from mortar fire until the canopy starts
to inflate, with one value per parachute type found empirically (the search
matches the dynamic pressure at deployment).  Here it is the parameter
``deployment_load[T]`` (N) of each parachute type T, estimated with the rest.

The load F acts along the vehicle's drag direction from the observed
``mortar_fire`` time t_m (switched on over the mortar's stroke, ON_S) until
the inflation start ``t_start[P,stage1]`` (switched off over OFF_S, centred
on it so the prediction stays smooth in the free start time).  It passes
through the riser, so a riser load cell reads it: list this effect after the
riser model and before the load-cell sensor.  Canopies without a
``mortar_fire`` event (static-line or tunnel deployments already under way
when the data begin) carry none.

Quantities written: ``deployment_force[P]`` (N), and ``tension[P]`` raised by it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.inflation import smoothstep
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest, Parachute
    from cpas_ocp.physics.model_context import ModelContext

ON_S = 0.03  # the load builds up over the mortar's stroke (s)
OFF_S = 0.02  # and ends over this time around the inflation start (s)
MAX_LOAD_N = 2.0e5  # upper bound of the estimated load (N), about 45,000 lbf


@dataclass(frozen=True)
class DeploymentLoad(Effect):
    """Inelastic deployment load per parachute type, from mortar fire to inflation start."""

    name: str = "deployment_load"

    def parameters(self, test: FlightTest) -> list[Parameter]:
        types = dict.fromkeys(c.type for c in self._deployed(test))
        return [Parameter(param_name("deployment_load", t), "N", 2000.0, 0.0, MAX_LOAD_N,
                          description="inelastic load while lines and risers deploy",
                          scale=2000.0, physical_lower=True) for t in types]

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No deployment load: F = 0 N (the lower bound)."""
        return {param_name("deployment_load", t): 0.0
                for t in dict.fromkeys(c.type for c in self._deployed(test))}

    @staticmethod
    def _deployed(test: FlightTest) -> list[Parachute]:
        return [c for c in test.parachutes if test.event("mortar_fire", c.name) is not None]

    def forces(self, ctx: ModelContext) -> None:
        e = ctx.q["drag_direction"]
        for chute in self._deployed(ctx.test):
            fired = ctx.test.event("mortar_fire", chute.name).time
            start = ctx.p[param_name("t_start", chute.name, chute.stages[0])]
            window = (smoothstep(2.0 * (ctx.t - fired) / ON_S - 1.0)
                      * (1.0 - smoothstep(2.0 * (ctx.t - start) / OFF_S)))
            force = ctx.p[param_name("deployment_load", chute.type)] * window
            ctx.q[param_name("deployment_force", chute.name)] = force
            ctx.forces.append(force * e)

    def observations(self, ctx: ModelContext) -> None:
        for chute in self._deployed(ctx.test):
            tension = param_name("tension", chute.name)
            if tension not in ctx.q:
                raise ValueError("list the deployment_load effect after the riser model: "
                                 "the load passes through the riser")
            cells = [s.name for s in ctx.test.sensors_of("load_cell")
                     if s.parachute == chute.name]
            if any(name in ctx.y for name in cells):
                raise ValueError("list the deployment_load effect before load_cell: the "
                                 "load cells read the load")
            ctx.q[tension] = ctx.q[tension] + ctx.q[param_name("deployment_force", chute.name)]
