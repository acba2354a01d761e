"""Canopies on inextensible risers, with their dry mass (paper Eq. 3).

Each canopy moves with the vehicle: its drag and its dry mass m_p are lumped
onto the vehicle body.  The riser tension follows from the canopy's own
equation of motion, m_p a = D + m_p g - T, i.e. T = D - m_p f with f the
system's specific force; along the drag direction this is the paper's
F = PRF*CdS*q - W_p*G.  With the `added_mass` effect the pull gains
-(d(m_A)/dt v_air + m_A a) (paper Eq. 1).  A riser cannot push: tension is clipped at zero by a
smooth maximum, (T + sqrt(T^2 + eps^2)) / 2 with eps = 50 N (under 2 N of
difference once the riser carries more than 600 N), so the estimation problem
stays differentiable where the canopy starts to pull.

Quantities written: ``tension[P]`` (N), along the riser: the axial pull over
cos(theta) where the `fly_out` effect sets a fly-out angle theta.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import param_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.model_context import ModelContext


SLACK_N = 50.0  # width of the smooth zero clip of riser tension (N)


def tension_only(force: ca.SX) -> ca.SX:
    """Riser force (N) clipped smoothly at zero: (F + sqrt(F^2 + eps^2)) / 2, eps = SLACK_N."""
    return 0.5 * (force + ca.sqrt(force**2 + SLACK_N**2))


def along_riser(ctx: ModelContext, chute: str, axial: ca.SX) -> ca.SX:
    """Riser tension (N) from its component along the drag axis: over cos(fly-out angle)."""
    return axial / ctx.q.get(param_name("axial_fraction", chute), 1.0)


@dataclass(frozen=True)
class RigidRiser(Effect):
    """Canopies on inextensible risers, with their dry mass (paper Eq. 3)."""

    name: str = "rigid_riser"

    def forces(self, ctx: ModelContext) -> None:
        for chute in ctx.test.parachutes:
            pull = ctx.q[param_name("drag", chute.name)]
            ctx.q[param_name("riser_force", chute.name)] = pull  # N, 3-vector on the vehicle
            ctx.forces.append(pull)
            ctx.mass = ctx.mass + chute.dry_mass

    def observations(self, ctx: ModelContext) -> None:
        f = ctx.q["specific_force"]
        a = f + ca.vertcat(0.0, 0.0, -G0)
        for chute in ctx.test.parachutes:
            pull = ctx.q[param_name("drag", chute.name)] - chute.dry_mass * f
            # Air mass the canopy carries (added_mass effect): the riser also gathers
            # it (d(m_A)/dt v_air) and decelerates it (m_A a).
            m_a = ctx.q.get(param_name("added_mass", chute.name))
            if m_a is not None:
                pull = pull - ctx.q[param_name("added_momentum_rate", chute.name)] - m_a * a
            axial = tension_only(ca.dot(pull, ctx.q["drag_direction"]))
            ctx.q[param_name("tension", chute.name)] = along_riser(ctx, chute.name, axial)
