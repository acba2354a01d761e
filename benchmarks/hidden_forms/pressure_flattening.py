"""A canopy whose drag area falls as the dynamic pressure rises (a truth for simulation only).

A porous canopy flattens and its cloth passes more air as the load grows, so
its drag coefficient falls with the dynamic pressure q:

    CdS_eff = CdS (q / q_ref)^(-k),   ``flattening_exponent`` = k,

with q_ref (`reference_pa`, Pa) the pressure at which the stated drag area
holds.  q is floored at 1 % of q_ref, where a canopy carries little load.  The
library's drag has no pressure dependence, and no template proposes one: the
data for the hidden-forms benchmark are made with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter

FLOOR_SHARE = 0.01  # q is floored at this share of q_ref


@dataclass(frozen=True)
class PressureFlattening(Effect):
    """Drag area times (q / q_ref)^(-k) for every canopy."""

    reference_pa: float = 1000.0
    name: str = "pressure_flattening"

    def parameters(self, test) -> list[Parameter]:
        return [Parameter("flattening_exponent", "1", 0.0, -0.5, 0.5, scale=0.05,
                          description="drag area's power of the dynamic pressure, negated")]

    def null_values(self, test) -> dict[str, float]:
        return {"flattening_exponent": 0.0}

    def forces(self, ctx) -> None:
        q = ca.fmax(ctx.q["dynamic_pressure"], FLOOR_SHARE * self.reference_pa)
        factor = (q / self.reference_pa) ** (-ctx.p["flattening_exponent"])
        for chute in ctx.test.parachutes:
            ctx.scale_drag(chute.name, factor, self.name, ("axial_fraction", "riser_force"))
