"""Per-stage drag scale factor: trajectory drag over load-cell-implied drag.

The paper scales each stage's drag so that the simulated trajectory matches
GPS after the riser drag areas were matched to the IMU (Section IV).  In one
joint estimation the trajectory and IMU fix the true drag, and the load cells
measure it through per-stage friction losses over the fairleads; so the
factor s_stage enters the load-cell prediction as 1/s_stage:

    reading = (k_P / s_stage) * T_P,

s > 1 meaning the load cells read low.  Only ratios of load-cell scales to
drag scales can be observed, so `LoadCellScale` fixes the common level.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext


@dataclass(frozen=True)
class DragScale(Effect):
    """``drag_scale[S]`` for every stage name S of a canopy with a load cell."""

    name: str = "drag_scale"

    @staticmethod
    def _measured(test: FlightTest) -> list:
        measured = {s.parachute for s in test.sensors_of("load_cell")}
        return [c for c in test.parachutes if c.name in measured]

    def parameters(self, test: FlightTest) -> list[Parameter]:
        stages = dict.fromkeys(s for c in self._measured(test) for s in c.stages)
        return [Parameter(param_name("drag_scale", s), "1", 1.0, 0.5, 2.0,
                          description="trajectory drag / load-cell drag in the stage", scale=1.0)
                for s in stages]

    def observations(self, ctx: ModelContext) -> None:
        for chute in self._measured(ctx.test):
            inverse = sum(ctx.q[param_name("stage_weight", chute.name, s)]
                          / ctx.p[param_name("drag_scale", s)] for s in chute.stages)
            ctx.scale(param_name("loadcell_gain", chute.name), inverse)
