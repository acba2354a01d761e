"""Forebody wake deficit: the canopy sees a fraction PRF of the free-stream dynamic pressure.

A canopy trailing in the forebody's wake inflates and pulls in slower air.
The paper's pressure recovery fraction PRF (Eqs. 2, 3) is the ratio of the
dynamic pressure at the canopy to the free stream's, so the canopy's drag is

    D_P = PRF_P CdS_P q_inf        (N)

and the offline reduction yields the product PRF*CdS.  ``prf[P]`` (1, in
(0, 1]) is a property of the parachute type and the forebody (a CFD or
campaign value, e.g. the paper's PTV wake against the PCDTV), set per
parachute type through the option `prf` ({type: value}; types not listed
get 1, no deficit).

Within one test PRF and the canopy's drag areas enter only as their product,
so the parameter is fixed by default: with it given, the reconstruction
reports free-stream drag areas that can be pooled across forebodies; without
it (PRF = 1) it reports PRF*CdS, as the paper's PCDTV reconstructions do.
List this effect after `canopy_inflation` and before `fly_out` and the riser
effects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

MIN_PRF = 0.2


@dataclass(frozen=True)
class WakeDeficit(Effect):
    """Pressure recovery fraction ``prf[P]`` per parachute type: the canopy's drag is PRF*CdS*q."""

    prf: dict[str, float] = field(default_factory=dict)
    name: str = "wake_deficit"

    def __post_init__(self) -> None:
        if not isinstance(self.prf, dict):
            raise ValueError("prf must map parachute types to fractions, e.g. {\"main\": 0.9}")
        for kind, value in self.prf.items():
            if not isinstance(value, int | float) or not MIN_PRF <= float(value) <= 1.0:
                raise ValueError(f"prf of {kind!r} must lie in [{MIN_PRF}, 1]; got {value}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("prf", c.name), "1", float(self.prf.get(c.type, 1.0)),
                          MIN_PRF, 1.0, description="pressure recovery fraction in the wake",
                          scale=1.0, free_by_default=False, physical_upper=True)
                for c in test.parachutes]

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """Free stream: PRF = 1 (the upper bound; the alternative is a deficit, PRF < 1).

        Within one test PRF*CdS is all the data see, so the test is informative
        only where the drag areas are known otherwise (priors on `CdS[P,S]`).
        """
        return {param_name("prf", c.name): 1.0 for c in test.parachutes}

    def forces(self, ctx: ModelContext) -> None:
        for chute in ctx.test.parachutes:
            ctx.scale_drag(chute.name, ctx.p[param_name("prf", chute.name)], self.name,
                           ("axial_fraction", "riser_force"))
