"""Sensor time lag: a sensor reports at t what the model says for t - tau.

GPS receivers report position and velocity with a filter and processing
delay of typically 0.05-0.2 s; a logger's clock may also sit a few tens of ms
off the others.  The parameter ``lag[<sensor>]`` (s, default 0) may take
either sign (negative: the sensor's clock runs behind).  The state at t - tau
comes from RK4 steps of the dynamics backwards from the state at t
(`ModelContext.at_time_offset`), at most `STEP_S` long, so the model stays a
function of the node state and is smooth in tau.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from ..parameters import Parameter, param_name
from .base import Effect

if TYPE_CHECKING:
    from ..flight_test import FlightTest
    from ..model import ModelContext

STEP_S = 0.05  # longest RK4 step of the backward integration (s)


@dataclass(frozen=True)
class SensorLag(Effect):
    """Time lag of every sensor of `kind`, |tau| <= `max_lag` (s).  Put it after the sensors."""

    kind: str = "gps"
    max_lag: float = 0.2
    name: str = "gps_lag"

    @classmethod
    def gps(cls) -> SensorLag:
        """GPS position and velocity lag, up to 0.2 s (four backward RK4 steps)."""
        return cls()

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("lag", s.name), "s", 0.0, -self.max_lag, self.max_lag,
                          scale=0.05, description=f"time lag of {s.name}")
                for s in test.sensors_of(self.kind)]

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No lag: tau = 0 s."""
        return {param_name("lag", s.name): 0.0 for s in test.sensors_of(self.kind)}

    def observations(self, ctx: ModelContext) -> None:
        steps = max(1, math.ceil(self.max_lag / STEP_S))
        for s in ctx.test.sensors_of(self.kind):
            channels = list(ctx.y[s.name])
            now = ca.vertcat(*(ctx.y[s.name][ch] for ch in channels))
            then = ctx.at_time_offset(now, -ctx.p[param_name("lag", s.name)], steps)
            ctx.y[s.name] = {ch: then[i] for i, ch in enumerate(channels)}
