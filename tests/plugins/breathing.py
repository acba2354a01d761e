"""Canopy breathing: the drag area of each canopy oscillates at a fixed frequency.

A full canopy's skirt pulses in and out (a few Hz for canopies of tens of
feet), so its drag area is CdS (1 + a cos(2 pi f t) + b sin(2 pi f t)).
The in-phase and quadrature amplitudes ``breathing_cos[P]`` and
``breathing_sin[P]`` (fractions of the drag area) enter linearly, so that the
effect vanishes at a = b = 0 (its score test's null) and the fit needs no
phase search.  The frequency ``breathing_frequency`` (Hz, shared by the
canopies) starts at the option `frequency`, read off the diagnosis's
periodogram, and is estimated with the rest; the score test holds it there
(under the null it has no effect).  With the option `onset_s` the pulsing
starts at that time (s), over a tanh ramp of ONSET_RAMP_S.  List the effect
after canopy_inflation, before the riser effects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

ONSET_RAMP_S = 0.2  # the pulsing's rise at `onset_s` (s)


@dataclass(frozen=True)
class Breathing(Effect):
    """Drag-area oscillation at `frequency` Hz, amplitudes ``breathing_cos/sin[P]``."""

    frequency: float = 3.0
    onset_s: float | None = None
    name: str = "breathing"

    def parameters(self, test) -> list[Parameter]:
        return [Parameter("breathing_frequency", "Hz", self.frequency, 0.5, 20.0, scale=1.0,
                          description="drag-area oscillation frequency"),
                *(Parameter(param_name(base, c.name), "1", 0.0, -0.3, 0.3, scale=0.05,
                            description=f"{part} drag-area oscillation amplitude")
                  for c in test.parachutes
                  for base, part in (("breathing_cos", "in-phase"),
                                     ("breathing_sin", "quadrature")))]

    def null_values(self, test) -> dict[str, float]:
        return {p.name: 0.0 for p in self.parameters(test)[1:]}

    def forces(self, ctx) -> None:
        phase = 2.0 * math.pi * ctx.p["breathing_frequency"] * ctx.t
        gate = 1.0 if self.onset_s is None else \
            0.5 * (1.0 + ca.tanh((ctx.t - self.onset_s) / ONSET_RAMP_S))
        for chute in ctx.test.parachutes:
            factor = (1.0 + gate * (ctx.p[param_name("breathing_cos", chute.name)] * ca.cos(phase)
                                    + ctx.p[param_name("breathing_sin", chute.name)]
                                    * ca.sin(phase)))
            ctx.scale_drag(chute.name, factor, self.name, ("axial_fraction", "riser_force"))
