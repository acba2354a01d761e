"""A load cell whose reading loses a share of the tension that grows with it.

    reading = T (1 - k T),  ``tension_loss[P]`` = k (1/N)

At k = 8e-6 /N a 19 kN peak reads 15 % low, a 5 kN steady load 4 % low: no
constant bias, scale or rate-dependent friction describes it.  The data for
the stand-in test are made with it; the library does not have it.
"""

from dataclasses import dataclass

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter, param_name


@dataclass(frozen=True)
class TensionLoss(Effect):
    """Reading loss growing with the tension, k (1/N) per load cell's canopy."""

    name: str = "tension_loss"

    def parameters(self, test):
        return [Parameter(param_name("tension_loss", s.parachute), "1/N", 0.0, -2e-5, 2e-5,
                          scale=1e-6, description="reading loss per newton of tension")
                for s in test.sensors_of("load_cell")]

    def null_values(self, test):
        return {param_name("tension_loss", s.parachute): 0.0
                for s in test.sensors_of("load_cell")}

    def observations(self, ctx):
        for s in ctx.test.sensors_of("load_cell"):
            tension = ctx.y[s.name]["tension"]
            k = ctx.p[param_name("tension_loss", s.parachute)]
            ctx.y[s.name]["tension"] = tension * (1.0 - k * tension)
