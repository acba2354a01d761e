"""Fly-out of the canopies in a cluster (paper Eq. 7).

The canopies of a cluster push each other apart, so each riser leans out of
the system's drag axis by its fly-out angle theta_i.  The riser carries the
canopy's whole pull T_i, and the load cell reads it; the vehicle is pulled
along the drag axis by T_i cos(theta_i) only.  The side components of a
symmetric cluster cancel, and are neglected.  So, with the model's drag area
CdS_i taken from the riser load (paper Eq. 3), the system's drag area is

    (CdS)_system = sum_i CdS_i cos(theta_i)        (paper Eq. 7)

The angle grows as the canopies open: ``flyout_angle[P,S]`` (rad) is the
angle of canopy P in stage S, and between stages it hands over along the
same smooth weights as the stage's sensor gains (`stage_weight[P,S]`).

The angles are inputs (video, photogrammetry), not estimated by default:
with a per-stage drag scale factor in the model, a common cos(theta) of a
stage is indistinguishable from that factor, and per-canopy differences from
the load-cell scales.  Name them in the model's ``free`` to estimate them
where the data allow.  `angles_deg` gives the defaults stage by stage (the
last value holds for later stages).

In the model the canopy's `drag[P]` becomes its axial part, CdS_i q
cos(theta_i), so everything downstream (the riser's equation of motion,
added mass) works along the axis; the riser effects divide the axial pull by
``axial_fraction[P]`` = cos(theta_i) to give the tension the load cell reads.
List this effect after `canopy_inflation` and before the riser and
added-mass effects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

MAX_ANGLE_DEG = 60.0


@dataclass(frozen=True)
class FlyOut(Effect):
    """Riser fly-out angle per canopy and stage; the vehicle feels T cos(theta) (Eq. 7)."""

    angles_deg: tuple[float, ...] = (10.0, 15.0, 20.0)
    name: str = "fly_out"

    def __post_init__(self) -> None:
        angles = tuple(float(a) for a in self.angles_deg)
        if not angles or any(not 0.0 <= a < MAX_ANGLE_DEG for a in angles):
            raise ValueError(f"angles_deg must be angles in [0, {MAX_ANGLE_DEG:g}) degrees")
        object.__setattr__(self, "angles_deg", angles)

    def parameters(self, test: FlightTest) -> list[Parameter]:
        out = []
        for chute in test.parachutes:
            for k, stage in enumerate(chute.stages):
                angle = self.angles_deg[min(k, len(self.angles_deg) - 1)]
                out.append(Parameter(param_name("flyout_angle", chute.name, stage), "rad",
                                     math.radians(angle), 0.0, math.radians(MAX_ANGLE_DEG),
                                     description="riser angle out of the drag axis",
                                     scale=0.3, free_by_default=False, physical_lower=True))
        return out

    def forces(self, ctx: ModelContext) -> None:
        for chute in ctx.test.parachutes:
            theta = sum(ctx.q[param_name("stage_weight", chute.name, s)]
                        * ctx.p[param_name("flyout_angle", chute.name, s)] for s in chute.stages)
            axial = ca.cos(theta)
            ctx.scale_drag(chute.name, axial, self.name, ("added_mass", "riser_force"))
            ctx.q[param_name("axial_fraction", chute.name)] = axial
