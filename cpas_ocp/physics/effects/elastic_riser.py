"""Each canopy its own body on an elastic riser: a spring-damper that carries tension only.

Instead of lumping the canopy onto the vehicle (`RigidRiser`), the canopy
moves along the riser line, the unit vector e from the vehicle toward the
trailing canopy (the vehicle's drag direction; its slow rotation is
neglected).  Its position along e, relative to the unstretched riser, is the
stretch s (m), a state with its rate s' (m/s).  The riser force is

    T = k_s s + c_s s'   (N),  k_s = m_p w^2,  c_s = 2 zeta m_p w,  w = 2 pi / P

clipped smoothly at zero once the canopy has left the vehicle (a riser cannot
push).  It is parameterised by the natural period P = ``riser_period[P]`` (s)
and damping ratio zeta = ``riser_damping_ratio[P]`` of the canopy's dry mass
m_p on the riser (the air mass m_A lengthens the actual period).  The bounds
(P down to 40 ms, i.e. 25 Hz; zeta up to 1) keep the fastest mode within RK4's
stability on grids of 10 ms and finer.

The period rather than the frequency is the decision variable because the
rigid riser is its limit P -> 0, which the model approaches smoothly: the
riser's static stretch grows as P^2 and the canopy's lag behind the vehicle
as P, while in the frequency both bend as 1/f^2 and 1/f, flattest exactly
where a confirming refit starts (the stiff null).  On `drogue` flown with
6 Hz risers and fitted with rigid ones, the refit from the score test's
linearised estimates converged in the period (49 iterations, with the
Levenberg term of `nlp_functions.ipopt_functions`) and stopped at its
150-iteration cap in the frequency.  From other starts it still may not
converge (see docs/validation.md).  On `main3_full` (three Mains
on elastic risers, with added mass) the full model converges from the
offline reduction in the period (62-67 iterations) and did not in 300 in
the frequency.

Before the canopy's first stage starts, the pack rides in the vehicle: the
link then also carries compression, and the switch from link to riser runs
smoothly over DEPLOY_S after the start, so the motion stays smooth in the
start time.

The canopy sees the air at V_c = V - s' (V the vehicle's airspeed), so its
drag is the `drag[P]` of the canopy-inflation effect times (V_c / V)^2.  Its
equation of motion along e (paper Eq. 1, m_c = m_p + m_A):

    m_c (a_v . e + s'') = D_c + m_p g . e - T + dm_A/dt V_c

with a_v the vehicle's acceleration; the vehicle feels T e and carries only
its own mass.  With the `added_mass` effect (listed after this one) m_A and
dm_A/dt come from it and stay with the canopy; without it m_c = m_p.  The
load cell reads T.

Quantities written: ``tension[P]`` (N), ``stretch[P]`` (m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import casadi as ca
import numpy as np

from cpas_ocp.physics.effects.base import Effect, State
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.effects.rigid_riser import along_riser, tension_only
from cpas_ocp.physics.inflation import smoothstep
from cpas_ocp.physics.parameters import Parameter, param_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

DEPLOY_S = 0.05  # time over which the packed link becomes a tension-only riser (s)
# Natural frequency (Hz; the upper end keeps RK4 stable on 10 ms grids) and damping ratio.
FREQUENCY_BOUNDS_HZ = (0.5, 25.0)
PERIOD_BOUNDS_S = (1.0 / FREQUENCY_BOUNDS_HZ[1], 1.0 / FREQUENCY_BOUNDS_HZ[0])
DAMPING_BOUNDS = (0.02, 1.0)
# A canopy whose observed start is this long after the phase begins is packed at the start (s).
PACKED_MARGIN_S = 0.5


@dataclass(frozen=True)
class ElasticRiser(Effect):
    """Spring-damper risers; `frequency` (Hz; the period parameter's default is its
    inverse) and `damping_ratio` are the defaults."""

    frequency: float = 8.0
    damping_ratio: float = 0.3
    name: str = "elastic_riser"
    replaces: ClassVar[str | None] = "rigid_riser"
    continuation: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for label, value, (lo, hi) in (("frequency", self.frequency, FREQUENCY_BOUNDS_HZ),
                                       ("damping_ratio", self.damping_ratio, DAMPING_BOUNDS)):
            if not isinstance(value, int | float) or not lo <= value <= hi:
                raise ValueError(f"{label} must be a number in [{lo:g}, {hi:g}]; got {value!r}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        out = []
        for c in test.parachutes:
            out += [
                Parameter(param_name("riser_period", c.name), "s", 1.0 / self.frequency,
                          *PERIOD_BOUNDS_S, scale=1.0 / self.frequency,
                          description="natural period of the dry canopy on its riser"),
                Parameter(param_name("riser_damping_ratio", c.name), "1", self.damping_ratio,
                          *DAMPING_BOUNDS, description="damping ratio of the riser", scale=0.3),
            ]
        return out

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """The stiffest riser the model resolves: the shortest period, zeta at its upper bound.

        A rigid riser is the limit P -> 0, which no positive value reaches;
        at 40 ms (25 Hz), critically damped, the canopy follows the vehicle with a lag
        of P / (2 pi) = 6 ms and no ringing, and the score test asks whether
        a softer or less damped riser explains the data better.
        """
        out = {}
        for c in test.parachutes:
            out[param_name("riser_period", c.name)] = PERIOD_BOUNDS_S[0]
            out[param_name("riser_damping_ratio", c.name)] = DAMPING_BOUNDS[1]
        return out

    def states(self, test: FlightTest) -> list[State]:
        """Stretch and its rate per canopy; zero and held there at the start of the phase
        when the canopy is still packed then (its first stage starts later)."""
        out = []
        for c in test.parachutes:
            packed = not c.open_at_start and \
                CanopyInflation.observed_start(test, c, 0) > test.t_start + PACKED_MARGIN_S
            out += [State(param_name("stretch", c.name), 1, "m", 0.1, pinned=packed),
                    State(param_name("stretch_rate", c.name), 1, "m/s", 1.0, pinned=packed)]
        return out

    def state_guess(self, test: FlightTest, t: np.ndarray,
                    values: dict[str, float]) -> dict[str, np.ndarray]:
        """Quasi-static stretch T / k_s from each canopy's load cell (smoothed over 5 samples)."""
        out = {}
        for cell in test.sensors_of("load_cell"):
            chute = test.parachute(cell.parachute)
            omega = 2.0 * math.pi / values[param_name("riser_period", chute.name)]
            tension = np.convolve(cell.data["tension"].to_numpy(), np.ones(5) / 5.0, mode="same")
            stretch = np.interp(t, cell.time, tension) / (chute.dry_mass * omega**2)
            out[param_name("stretch", chute.name)] = stretch
            out[param_name("stretch_rate", chute.name)] = np.gradient(stretch, t)
        return out

    def forces(self, ctx: ModelContext) -> None:
        e = ctx.q["drag_direction"]
        for chute in ctx.test.parachutes:
            ctx.separate_body(chute.name, self.name)
            s = ctx.x[param_name("stretch", chute.name)]
            s_dot = ctx.x[param_name("stretch_rate", chute.name)]
            omega = 2.0 * math.pi / ctx.p[param_name("riser_period", chute.name)]
            zeta = ctx.p[param_name("riser_damping_ratio", chute.name)]
            linear = chute.dry_mass * omega * (omega * s + 2.0 * zeta * s_dot)
            pulled = tension_only(linear)
            # A canopy open at the phase's start has its riser released throughout.
            t_deploy = (ctx.test.t_start - DEPLOY_S if chute.open_at_start
                        else ctx.p[param_name("t_start", chute.name, chute.stages[0])])
            released = smoothstep(2.0 * (ctx.t - t_deploy) / DEPLOY_S - 1.0)
            ctx.q[param_name("riser_force", chute.name)] = (
                (1.0 - released) * linear + released * pulled)
            ctx.q[param_name("tension", chute.name)] = along_riser(ctx, chute.name, pulled)
            ctx.q[param_name("stretch", chute.name)] = s
            ctx.forces.append(ctx.q[param_name("riser_force", chute.name)] * e)

    def observations(self, ctx: ModelContext) -> None:
        e = ctx.q["drag_direction"]
        a_v = ctx.q["specific_force"] + ca.vertcat(0.0, 0.0, -G0)
        gravity_along = ca.dot(ca.vertcat(0.0, 0.0, -G0), e)
        airspeed = ctx.q["airspeed"]
        for chute in ctx.test.parachutes:
            s_dot = ctx.x[param_name("stretch_rate", chute.name)]
            v_c = airspeed - s_dot
            drag = ca.dot(ctx.q[param_name("drag", chute.name)], e) * (v_c / airspeed) ** 2
            m_c = chute.dry_mass
            push = drag + chute.dry_mass * gravity_along - ctx.q[param_name("riser_force",
                                                                              chute.name)]
            m_a = ctx.q.get(param_name("added_mass", chute.name))
            if m_a is not None:
                m_c = m_c + m_a
                # -dm_A/dt v_air . e = dm_A/dt V for the vehicle's air; the canopy's is V_c.
                gathered = -ca.dot(ctx.q[param_name("added_momentum_rate", chute.name)], e)
                push = push + gathered * v_c / airspeed
            ctx.xdot[param_name("stretch", chute.name)] = s_dot
            ctx.xdot[param_name("stretch_rate", chute.name)] = push / m_c - ca.dot(a_v, e)
