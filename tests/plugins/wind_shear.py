"""A shear layer: a horizontal wind that grows with altitude through a layer.

    u_east(h) = S L tanh((h - H_MID_M) / L),   L = LAYER_M

``shear_rate`` = S (1/s) is the wind's gradient at the layer's middle
H_MID_M: at 0.03 /s the east wind changes by 30 m/s per km there, and by
2 S L = 18 m/s across the layer.  Not linear in altitude, so no constant or
linear profile describes it exactly.  The data for the hidden-wind tests are
made with it; the library does not have it.  List it first, before any drag.
"""

from dataclasses import dataclass

import casadi as ca

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter

H_MID_M = 6800.0  # the layer's middle (m)
LAYER_M = 300.0  # the layer's half-thickness scale (m)


@dataclass(frozen=True)
class WindShear(Effect):
    """East wind S L tanh((h - H_MID_M) / L) on top of the atmosphere's."""

    name: str = "wind_shear"

    def parameters(self, test):
        return [Parameter("shear_rate", "1/s", 0.0, -0.1, 0.1, scale=0.01,
                          description="wind gradient at the layer's middle")]

    def null_values(self, test):
        return {"shear_rate": 0.0}

    def forces(self, ctx):
        h = ctx.x["position"][2]
        east = ctx.p["shear_rate"] * LAYER_M * ca.tanh((h - H_MID_M) / LAYER_M)
        ctx.add_air_velocity(ca.vertcat(east, 0.0, 0.0), self.name)
