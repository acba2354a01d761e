"""A drag area that depends on the flow: terms of a regression the data select.

The library's canopies keep their drag area whatever the flow does; a porous
canopy that flattens under load, or a drag coefficient that follows the
Reynolds number, do not.  Where no effect named explains a misfit,
`discover` estimates the missing dependence as a sparse combination of
dimensionless features of the flow (`discrepancy.sparse_terms`), each
canopy's drag multiplied by

    exp(sum_k c_k phi_k),       ``drag_term[k]`` = c_k  (null 0),

the same coefficients for every canopy (one law of the canopy design), with
the features

* ``log_dynamic_pressure``: ln(q / q_ref), q floored at 1 % of q_ref (a
  power law CdS ∝ q^c, a canopy that flattens or fills under load);
* ``log_density``: ln(rho / rho_ref) (with the first, a power of the
  airspeed and the density apart: Reynolds-number and altitude effects);
* ``log_dynamic_pressure_squared``: ln(q / q_ref)^2 (a power that changes
  with the load).

q_ref (Pa) and rho_ref (kg/m^3) are the fit's median dynamic pressure and
density, so each coefficient is a logarithmic sensitivity about the phase's
typical flow and the drag areas keep their meaning there.  The option
`terms` lists the features used.
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

FEATURES = ("log_dynamic_pressure", "log_density", "log_dynamic_pressure_squared")
FLOOR_SHARE = 0.01  # q is floored at this share of q_ref
LIMIT = 1.0  # bound on each coefficient (a factor e per unit of its feature)


def term_name(feature: str) -> str:
    """The coefficient of `feature`: ``drag_term[feature]``."""
    return param_name("drag_term", feature)


@dataclass(frozen=True)
class DragLawTerms(Effect):
    """Every canopy's drag times exp(sum of ``drag_term[k]`` times feature k); see the
    module docstring.  `reference_pa` q_ref (Pa), `reference_density` rho_ref (kg/m^3)."""

    terms: tuple[str, ...] = FEATURES
    reference_pa: float = 1000.0
    reference_density: float = 1.0
    name: str = "drag_law_terms"

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))  # a model file's list
        unknown = [t for t in self.terms if t not in FEATURES]
        if unknown or not self.terms or len(set(self.terms)) != len(self.terms):
            raise ValueError(f"terms must be distinct names among {', '.join(FEATURES)}; "
                             f"got {list(self.terms)!r}")
        for label, value in (("reference_pa", self.reference_pa),
                             ("reference_density", self.reference_density)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{label} must be a positive number; got {value!r}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(term_name(t), "1", 0.0, -LIMIT, LIMIT, scale=0.05,
                          description=f"drag area's logarithmic sensitivity to {t}")
                for t in self.terms]

    def null_values(self, test: FlightTest) -> dict[str, float]:
        return {term_name(t): 0.0 for t in self.terms}

    def forces(self, ctx: ModelContext) -> None:
        q = ca.fmax(ctx.q["dynamic_pressure"], FLOOR_SHARE * self.reference_pa)
        log_q = ca.log(q / self.reference_pa)
        feature = {"log_dynamic_pressure": log_q,
                   "log_density": ca.log(ctx.q["density"] / self.reference_density),
                   "log_dynamic_pressure_squared": log_q**2}
        factor = ca.exp(sum(ctx.p[term_name(t)] * feature[t] for t in self.terms))
        for chute in ctx.test.parachutes:
            ctx.scale_drag(chute.name, factor, self.name, ("axial_fraction", "riser_force"))
