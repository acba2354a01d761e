"""Constant additive sensor bias: y = h(x) + b on one channel of every sensor of a kind.

Examples: an accelerometer whose load factor reads b (g) high after an
imperfect zero; a riser load cell with a zero offset of b (N).  The bias
parameter is ``bias[<sensor>,<channel>]``, default 0, estimable.  A bias is
told from a scale factor by the data's range: it shifts light and heavy loads
alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

# A plausible zero offset, as a share of the largest reading of the test: instruments
# specify theirs against full scale, a load cell's typically within 0.5-1 % of it, and a
# test's largest reading lies below full scale; twice the loosest of those is generous.
PLAUSIBLE_BIAS_SHARE = 0.02


@dataclass(frozen=True)
class SensorBias(Effect):
    """Bias on `channel` of every sensor of `kind`, in `unit` (the channel's model unit).

    `bound` limits |b|; `scale` is its typical size (NLP scaling).
    """

    kind: str = "imu_load_factor"
    channel: str = "load_factor"
    unit: str = "g"
    bound: float = 0.5
    scale: float = 0.01
    name: str = "imu_bias"

    @classmethod
    def imu(cls) -> SensorBias:
        """IMU load-factor bias (g), up to 0.5 g."""
        return cls()

    @classmethod
    def load_cell(cls) -> SensorBias:
        """Riser load-cell zero offset (N), up to 10 kN."""
        return cls("load_cell", "tension", "N", 1.0e4, 100.0, "loadcell_bias")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("bias", s.name, self.channel), self.unit, 0.0,
                          -self.bound, self.bound, scale=self.scale,
                          description=f"additive bias of {s.name}.{self.channel}")
                for s in test.sensors_of(self.kind)]

    def plausible(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """A zero offset is small against what the sensor reads: within PLAUSIBLE_BIAS_SHARE
        of the largest reading of the test.  A larger one (a load cell's 1.2 kN "bias" that
        is a loss growing with tension) marks a stand-in."""
        out = {}
        for s in test.sensors_of(self.kind):
            values = np.asarray(s.data[self.channel], dtype=float)
            largest = float(np.nanmax(np.abs(values))) if values.size else 0.0
            limit = PLAUSIBLE_BIAS_SHARE * largest
            out[param_name("bias", s.name, self.channel)] = (-limit, limit)
        return out

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No bias: b = 0."""
        return {param_name("bias", s.name, self.channel): 0.0 for s in test.sensors_of(self.kind)}

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of(self.kind):
            ctx.y[s.name][self.channel] = (ctx.y[s.name][self.channel]
                                           + ctx.p[param_name("bias", s.name, self.channel)])
