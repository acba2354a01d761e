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

d(m_A)/dt = dm_A/dt|_canopy (through dCdS/dt) + dm_A/drho * drho/dz * v_z,
taken as its average over RATE_WINDOW_S = 40 ms (a central difference along
the trajectory).  The Eq. 5/6 drag area turns sharply at a stage's start, at
the over-inflation peak and at the end of settling; there the exact rate
changes within a few ms, less than a load cell's sampling interval, and the
chi-square surface becomes rippled in the parameters that move those corners
(Ipopt stopped in different ripples from different starts).  Averaged over
four 100 Hz samples the load stays smooth to the data, and it remains short
against the fill times (0.1-0.5 s).

How the air mass grows through the fill is the least known part of the law:
the option `size_exponent` e makes it rho (r_p D_o)^3 (CdS / CdS_o)^(e/2), the
D^3 law at e = 3 (the default), later growth above it.  With `exponent_free`
the exponent is a parameter, ``added_mass_exponent``, shared by the canopies
(how air gathers is a property of the canopy design and the fill, like k_A);
it starts at `size_exponent`, the value at which the refined law is the
fixed one (`refinements`: what `discover` tries where the fixed law leaves
the inflation windows off the noise).

Quantities written: ``added_mass[P]`` (kg) and ``added_momentum_rate[P]``
(N, 3-vector, d(m_A)/dt v_air).  Riser models read both.  A canopy on
an elastic riser (listed before this effect) keeps its air mass in its own
equation of motion; otherwise the air mass rides on the vehicle body.

Estimation: on `fbcp` (k_A = 1.4) the factors are recovered from the
reduction's guess in 11-15 iterations with sigma 0.09; on `drogue`
(seeds 4-6) the fit converges to the truth's basin from the reduction in
21-108 iterations with sigma 0.03.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Effect, Refinement
from cpas_ocp.physics.parameters import Parameter, param_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

K_ENCLOSED = 1.0
K_APPARENT = 0.5
PROJECTED_RATIO = 0.7
# Keeps d(CdS^1.5)/dCdS finite where a canopy has no drag area yet (m^2).
CDS_FLOOR = 1e-4
# Largest growth exponent of the air mass in the canopy's size (rho D^e; 3 is the D^3 law).
MAX_SIZE_EXPONENT = 12.0
# Smallest fitted exponent: below it the air mass is nearly all there at the fill's start.
MIN_SIZE_EXPONENT = 0.5
EXPONENT = "added_mass_exponent"
# Averaging window of the added-mass growth rate (s), well below the fill times (0.1-1 s).
RATE_WINDOW_S = 0.04


@dataclass(frozen=True)
class AddedMass(Effect):
    """Added mass of each canopy: enclosed plus apparent air mass, growing with the canopy.

    `size_exponent` e: the air mass grows as (CdS / CdS_o)^(e / 2) through the fill, 3
    for the rho D^3 law (above 3 the air gathers late in the fill, as where the enclosed
    mass fills only once the mouth is round); `exponent_free`: e is estimated
    (``added_mass_exponent``), starting at `size_exponent`; see the module docstring."""

    size_exponent: float = 3.0
    exponent_free: bool = False
    name: str = "added_mass"

    def __post_init__(self) -> None:
        e = self.size_exponent
        if isinstance(e, bool) or not (isinstance(e, int | float) and math.isfinite(e)
                                       and 0.0 < e <= MAX_SIZE_EXPONENT):
            raise ValueError(f"size_exponent must be a number in (0, {MAX_SIZE_EXPONENT:g}]; "
                             f"got {e!r}")
        if not isinstance(self.exponent_free, bool):
            raise ValueError(f"exponent_free must be true or false; got {self.exponent_free!r}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        factors = [Parameter(param_name("added_mass_factor", c.name), "1", 1.0, 0.0, 5.0,
                             description="added mass over its nominal value", scale=1.0,
                             physical_lower=True)
                   for c in test.parachutes]
        if not self.exponent_free:
            return factors
        start = min(max(self.size_exponent, MIN_SIZE_EXPONENT), MAX_SIZE_EXPONENT)
        return [*factors, Parameter(EXPONENT, "1", start, MIN_SIZE_EXPONENT,
                                    MAX_SIZE_EXPONENT, scale=1.0,
                                    description="growth exponent of the air mass in the "
                                                "canopy's projected diameter (3: rho D^3)")]

    def refinements(self, test: FlightTest) -> list[Refinement]:
        """The law with its growth exponent estimated, null at `size_exponent`, refitted
        from there and from half and twice it (within the exponent's bounds)."""
        e = self.size_exponent
        if self.exponent_free or e < MIN_SIZE_EXPONENT:
            return []
        starts = tuple({EXPONENT: s} for s in (0.5 * e, 2.0 * e)
                       if MIN_SIZE_EXPONENT <= s <= MAX_SIZE_EXPONENT)
        return [Refinement(replace(self, exponent_free=True),
                           f"its growth exponent in the canopy's size freed (D^e, e = {e:g} "
                           "fixed)", {EXPONENT: e}, starts)]

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No air mass: k_A = 0 (on the lower bound; the alternative is k_A > 0)."""
        return {param_name("added_mass_factor", c.name): 0.0 for c in test.parachutes}

    def forces(self, ctx: ModelContext) -> None:
        r, v = ctx.x["position"], ctx.x["velocity"]
        v_air = -ctx.q["airspeed"] * ctx.q["drag_direction"]
        for chute in ctx.test.parachutes:
            cds = ctx.q[param_name("cds", chute.name)]
            # Full open: the last stage's drag area, or the current one of a canopy open at
            # the start (steady, possibly banded in altitude).
            cds_o = cds if chute.open_at_start else ctx.p[param_name("CdS", chute.name,
                                                                     chute.stages[-1])]
            # (D / D_full)^e with D = r_p D_o sqrt(CdS / CdS_o): the rho D^3 law at e = 3.
            exponent = ctx.p[EXPONENT] if self.exponent_free else self.size_exponent
            growth = ((cds + CDS_FLOOR) / cds_o) ** (0.5 * exponent)
            m_a = (ctx.p[param_name("added_mass_factor", chute.name)] * ctx.q["density"]
                   * math.pi * (PROJECTED_RATIO * chute.diameter)**3 * growth
                   * (K_ENCLOSED / 12.0 + K_APPARENT / 8.0))
            rate = _box_rate(m_a, ctx.t, r, v)
            momentum_rate = rate * v_air
            ctx.q[param_name("added_mass", chute.name)] = m_a
            ctx.q[param_name("added_momentum_rate", chute.name)] = momentum_rate
            if chute.name in ctx.separate_bodies:
                continue  # the canopy's own equation of motion carries its air mass
            ctx.mass = ctx.mass + m_a
            # The gathered air's momentum, and its weight carried by buoyancy, not the system.
            ctx.forces.append(-momentum_rate + m_a * ca.vertcat(0.0, 0.0, G0))


def _box_rate(m_a: ca.SX, t: ca.SX, r: ca.SX, v: ca.SX) -> ca.SX:
    """d(m_A)/dt averaged over RATE_WINDOW_S along the trajectory (kg/s).

    The central difference (m_A(t + w/2) - m_A(t - w/2)) / w, with the
    position moved by v w/2 either way (for the density).  The Eq. 5/6 drag
    area has corners (at the start of a stage, at the over-inflation peak, at
    the end of the settling), where the exact derivative jumps; the averaged
    rate is continuous, so the predicted loads stay continuous in the
    parameters that move the corners.
    """
    half = 0.5 * RATE_WINDOW_S
    ahead = ca.substitute(m_a, ca.vertcat(t, r), ca.vertcat(t + half, r + half * v))
    behind = ca.substitute(m_a, ca.vertcat(t, r), ca.vertcat(t - half, r - half * v))
    return (ahead - behind) / RATE_WINDOW_S
