"""A load cell whose amplifier saturates (a truth for simulation only).

    reading = T_sat tanh(T / T_sat),   ``saturation_tension[P]`` = T_sat (N)

At T_sat = 80 kN a 45 kN peak reads 10 % low and a 5 kN steady load 0.1 %
low: odd in the tension, unlike the quadratic loss of a friction or gain
law, and unlike any bias or scale.  The data for the hidden-forms benchmark
are made with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter, param_name


@dataclass(frozen=True)
class SaturatingLoadCell(Effect):
    """Each load cell reads T_sat tanh(T / T_sat)."""

    name: str = "saturating_load_cell"

    def parameters(self, test) -> list[Parameter]:
        return [Parameter(param_name("saturation_tension", s.parachute), "N", 1e9, 1e4, 1e9,
                          scale=1e4, description="tension at which the reading saturates")
                for s in test.sensors_of("load_cell")]

    def null_values(self, test) -> dict[str, float]:
        return {param_name("saturation_tension", s.parachute): 1e9
                for s in test.sensors_of("load_cell")}

    def observations(self, ctx) -> None:
        for s in ctx.test.sensors_of("load_cell"):
            tension = ctx.y[s.name]["tension"]
            limit = ctx.p[param_name("saturation_tension", s.parachute)]
            ctx.y[s.name]["tension"] = limit * ca.tanh(tension / limit)
