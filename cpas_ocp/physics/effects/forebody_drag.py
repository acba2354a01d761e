"""Forebody (vehicle) drag: F = (CdS)_V * q_inf, against the air-relative velocity."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext


@dataclass(frozen=True)
class ForebodyDrag(Effect):
    """Vehicle drag with drag area ``CdS_V`` (m^2), by default the manifest's value, fixed."""

    name: str = "forebody_drag"

    def parameters(self, test: FlightTest) -> list[Parameter]:
        cds = test.vehicle.forebody_cds
        return [Parameter("CdS_V", "m^2", cds, 0.0, max(4.0 * cds, 1.0),
                          description="forebody drag area", scale=max(cds, 1.0),
                          free_by_default=False, physical_lower=True)]

    def forces(self, ctx: ModelContext) -> None:
        ctx.forces.append(ctx.p["CdS_V"] * ctx.q["dynamic_pressure"] * ctx.q["drag_direction"])
