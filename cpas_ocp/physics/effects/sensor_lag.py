"""Sensor time lag: a sensor reports at t what the model says for t - tau.

GPS receivers report position and velocity with a filter and processing
delay of typically 0.05-0.3 s; a logger's clock may also sit a few tens of ms
off the others.  The parameter ``lag[<sensor>]`` (s, default 0) may take
either sign (negative: the sensor's clock runs behind).  The state at t - tau
comes from STEPS RK4 steps of tau / STEPS of the dynamics backwards from the
state at t (`ModelContext.at_time_offset`), so the model stays a function of
the node state and is smooth in tau.

The number of steps is fixed, not set by the bound: the steps shorten with
the lag the data show, and a wide bound costs nothing.  Against the exact
lagged output of the `drogue` truth trajectory (1 ms steps), the largest
error over a whole phase, inflations included, is 0.007 sigma (GPS vertical
velocity, sigma 0.1 m/s) at tau = 0.1 s, 0.034 sigma at 0.2 s, 0.078 sigma at
0.3 s and 0.23 sigma at 0.5 s (one sample at the drogue's peak load);
positions are ten times better.  When the number of steps grew with the
bound (50 ms each), so did the model's generated code: compiling a `drogue`
fit took 3.1 GB at +-0.2 s, 5.9 GB at +-0.3 s and 14.1 GB at +-0.5 s (build
30, 59 and 141 s), while +-0.2 s bound a true 0.25 s lag (reported as 0.2 s,
chi-square 173 higher).  Now every bound takes 3.1 GB and 40 s
(`benchmarks/lag_bound_cost.py`).

A model with elastic risers cannot have a lag: integrated backwards, a riser's
damped mode grows as exp(zeta omega tau), so the lagged prediction is
ill-conditioned whatever the integrator, and the composition is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

STEPS = 4  # RK4 steps of the backward integration, each tau / STEPS long


@dataclass(frozen=True)
class SensorLag(Effect):
    """Time lag of every sensor of `kind`, |tau| <= `max_lag` (s).  Put it after the sensors."""

    kind: str = "gps"
    max_lag: float = 0.5
    name: str = "gps_lag"

    @classmethod
    def gps(cls) -> SensorLag:
        """GPS position and velocity lag, up to 0.5 s either way."""
        return cls()

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name("lag", s.name), "s", 0.0, -self.max_lag, self.max_lag,
                          scale=0.05, description=f"time lag of {s.name}")
                for s in test.sensors_of(self.kind)]

    def plausible(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """A sensor's lag (its filter, its report's latency) is positive: a measurement
        cannot trail the event by a negative time.  The estimate may go either way (so
        that no lag is an interior point); a negative one marks a stand-in."""
        return {param_name("lag", s.name): (0.0, self.max_lag)
                for s in test.sensors_of(self.kind)}

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """No lag: tau = 0 s."""
        return {param_name("lag", s.name): 0.0 for s in test.sensors_of(self.kind)}

    def observations(self, ctx: ModelContext) -> None:
        if ctx.separate_bodies:
            # Backwards, a damped riser mode grows as exp(zeta omega tau): at the refit's
            # start on `drogue` (period 0.06 s, damping 0.94) that is x20,000 over a 0.1 s
            # lag, and the refit ran for over 20 minutes through non-finite values.
            raise ValueError(f"{self.name} cannot be combined with elastic risers: the state "
                             "at t - tau comes from the dynamics integrated backwards, in "
                             "which a damped riser mode grows without bound")
        for s in ctx.test.sensors_of(self.kind):
            channels = list(ctx.y[s.name])
            now = ca.vertcat(*(ctx.y[s.name][ch] for ch in channels))
            then = ctx.at_time_offset(now, -ctx.p[param_name("lag", s.name)], STEPS)
            ctx.y[s.name] = {ch: then[i] for i, ch in enumerate(channels)}
