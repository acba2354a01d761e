"""Per-canopy load-cell scale (calibration and friction), normalised to geometric mean 1.

Reading = k_P * (true tension) * (any other gains).  Because a common factor
of all load-cell scales cannot be told apart from the per-stage drag scale
factors, the k_P are normalised: sum_P log k_P = 0.  With a single measured
canopy its k is therefore 1 and the drag scales carry the whole level.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Constraint, Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext


@dataclass(frozen=True)
class LoadCellScale(Effect):
    name: str = "loadcell_scale"

    @staticmethod
    def _canopies(test: FlightTest) -> list[str]:
        return list(dict.fromkeys(s.parachute for s in test.sensors_of("load_cell")))

    def parameters(self, test: FlightTest) -> list[Parameter]:
        canopies = self._canopies(test)
        return [Parameter(param_name("loadcell_scale", c), "1", 1.0, 0.5, 2.0,
                          estimable=len(canopies) > 1,
                          description="load-cell reading / true tension (relative)", scale=1.0)
                for c in canopies]

    def observations(self, ctx: ModelContext) -> None:
        for c in self._canopies(ctx.test):
            ctx.scale(param_name("loadcell_gain", c), ctx.p[param_name("loadcell_scale", c)])

    def constraints(self, ctx: ModelContext) -> list[Constraint]:
        canopies = self._canopies(ctx.test)
        if len(canopies) < 2:
            return []
        expr = sum(ca.log(ctx.p[param_name("loadcell_scale", c)]) for c in canopies)
        return [Constraint("geometric mean of load-cell scales = 1", expr, 0.0, 0.0)]
