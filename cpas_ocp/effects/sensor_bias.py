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

from ..parameters import Parameter, param_name
from .base import Effect

if TYPE_CHECKING:
    from ..flight_test import FlightTest
    from ..model import ModelContext


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

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No bias: b = 0."""
        return {param_name("bias", s.name, self.channel): 0.0 for s in test.sensors_of(self.kind)}

    def observations(self, ctx: ModelContext) -> None:
        for s in ctx.test.sensors_of(self.kind):
            ctx.y[s.name][self.channel] = (ctx.y[s.name][self.channel]
                                           + ctx.p[param_name("bias", s.name, self.channel)])
