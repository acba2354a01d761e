"""Added mass of each canopy: enclosed plus apparent air mass, growing with the canopy.

The canopy drags along the air inside it (enclosed mass m_e) and the air it
displaces around it (apparent mass m_a).  Both scale like rho D^3, with the
projected diameter following the drag area, D = r_p D_o sqrt(CdS / CdS_o)
(CdS_o the full-open steady drag area, r_p = 0.7 the inflated projected
diameter over the nominal one, typical of ribbon and ringsail canopies):

    m_A = k_A rho pi D^3 (k_e / 12 + k_a / 8)        (kg)

with the nominal coefficients k_e = 1 (a hemisphere of diameter D enclosed)
and k_a = 0.5 (the GUIDE's DSS-derived forms), and `added_mass_factor[P]` =
k_A scaling both, since they cannot be told apart: they share the rho D^3
law.  The air mass is neutrally buoyant, moves with the canopy, and is
gathered from rest relative to the air, so the canopy (paper Eq. 1) obeys

    (m_p + m_A) a = D + m_p g - d(m_A)/dt v_air + (riser force),

and the pull the riser transmits gains -(d(m_A)/dt v_air + m_A a): the
opening load rises while the canopy grows (v_air points against the pull)
and falls while the canopy decelerates.  With rigid
risers the whole system gains m_A in inertia, the force -d(m_A)/dt v_air,
and no weight for m_A.

d(m_A)/dt = dm_A/dt|_canopy (through dCdS/dt) + dm_A/drho * drho/dz * v_z.

Quantities written: ``added_mass[P]`` (kg) and ``added_momentum_rate[P]``
(N, 3-vector, d(m_A)/dt v_air).  Riser models read both.

Status: simulation is tested; estimation with this effect is not yet
reliable.  On the drogue problem (k_A = 1.4) the 10 ms transcription is
accurate (chi-square at the truth 7097.7 for 7209 residuals), but Ipopt
with the Gauss-Newton Hessian does not converge in 500 iterations from the
reduction's initial guess, whose Ck has absorbed the added-mass loads.
Near each start, d(m_A)/dt grows like (t - t_i)^(expopen - 1), so its
derivative in t_i is unbounded for expopen < 2; making expopen >= 2.2 did
not fix the convergence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from ..parameters import Parameter, param_name
from ..units import G0
from .base import Effect

if TYPE_CHECKING:
    from ..flight_test import FlightTest
    from ..model import ModelContext

K_ENCLOSED = 1.0
K_APPARENT = 0.5
PROJECTED_RATIO = 0.7
# Keeps d(CdS^1.5)/dCdS finite where a canopy has no drag area yet (m^2).
CDS_FLOOR = 1e-4


@dataclass(frozen=True)
class AddedMass(Effect):
    name: str = "added_mass"

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("added_mass_factor", c.name), "1", 1.0, 0.0, 5.0,
                          description="added mass over its nominal value", scale=1.0)
                for c in test.parachutes]

    def forces(self, ctx: ModelContext) -> None:
        r, v = ctx.x["position"], ctx.x["velocity"]
        v_air = -ctx.q["airspeed"] * ctx.q["drag_direction"]
        for chute in ctx.test.parachutes:
            cds = ctx.q[param_name("cds", chute.name)]
            cds_o = ctx.p[param_name("CdS", chute.name, chute.stages[-1])]
            diameter = PROJECTED_RATIO * chute.diameter * ca.sqrt((cds + CDS_FLOOR) / cds_o)
            m_a = (ctx.p[param_name("added_mass_factor", chute.name)] * ctx.q["density"]
                   * math.pi * diameter**3 * (K_ENCLOSED / 12.0 + K_APPARENT / 8.0))
            rate = ca.jacobian(m_a, ctx.t) + ca.mtimes(ca.jacobian(m_a, r), v)
            momentum_rate = rate * v_air
            ctx.q[param_name("added_mass", chute.name)] = m_a
            ctx.q[param_name("added_momentum_rate", chute.name)] = momentum_rate
            ctx.mass = ctx.mass + m_a
            # The gathered air's momentum, and its weight carried by buoyancy, not the system.
            ctx.forces.append(-momentum_rate + m_a * ca.vertcat(0.0, 0.0, G0))
