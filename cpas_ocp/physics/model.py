"""Compose effects into the dynamics and the sensor predictions of a test phase.

The core body is the vehicle as a point mass in a flat-earth east-north-up
frame, 3 translational degrees of freedom, attitude not modelled (drag acts
against the air-relative velocity).  Its states are position r (m) and
velocity v (m/s).  Effects add forces and masses (canopies, forebody drag),
states of their own, and sensor predictions.  Between the two effect passes
the model forms

    specific force  f = sum(F) / m            (m/s^2, what an accelerometer senses)
    acceleration    a = f + g,  g = (0, 0, -g0)

with m the total mass carried on the vehicle body (vehicle plus anything an
effect lumps onto it, e.g. canopies on rigid risers).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, TypeVar

import casadi as ca
import numpy as np

from cpas_ocp.physics.effects.base import Capture, Constraint, Effect, EventTiming, State
from cpas_ocp.physics.model_context import SLOT_PREFIX, ModelContext
from cpas_ocp.physics.parameters import Parameter, param_name, split_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import Event, FlightTest

T = TypeVar("T", Parameter, State, Capture)

CORE_STATES = (
    State("position", 3, "m", 1000.0),
    State("velocity", 3, "m/s", 100.0),
)


class Model:
    """Dynamics x' = f(x, t, p, c) and sensor outputs y = h(x, t, p, c) of one test phase."""

    def __init__(self, test: FlightTest, effects: Sequence[Effect],
                 series_slots: int = 0) -> None:
        """The model of `effects` on `test`.  With `series_slots` L > 0 it is local in time:
        each series of parameter knots (`ModelContext.time_series`) reads L consecutive
        knots through slot symbols appended to the parameter vector (`slot_columns`), for
        the estimator's pieces; the knots' own parameters then act on nothing."""
        self.test = test
        self.effects = tuple(effects)
        self.parameters: list[Parameter] = _unique_by_name(
            [p for e in self.effects for p in e.parameters(test)], "parameter")
        self.states: list[State] = _unique_by_name(
            [*CORE_STATES, *(s for e in self.effects for s in e.states(test))], "state")
        self.timings = self._observed_timings()
        self.captures: list[Capture] = _unique_by_name(
            [c for e in self.effects for c in e.captures(test)]
            + [c for timing, event in self.timings for c in _crossing_captures(timing, event)],
            "capture")
        names = {p.name for p in self.parameters}
        for cap in self.captures:
            if cap.at_time is None and cap.time_parameter not in names:
                raise ValueError(f"capture {cap.name} refers to unknown parameter "
                                 f"{cap.time_parameter}")

        self.nx = sum(s.size for s in self.states)
        x = ca.SX.sym("x", self.nx)
        t = ca.SX.sym("t")
        p = ca.SX.sym("p", len(self.parameters))
        c = ca.SX.sym("c", len(self.captures))
        xs, k = {}, 0
        for s in self.states:
            xs[s.name] = x[k:k + s.size]
            k += s.size
        ctx = ModelContext(
            test=test, t=t, x=xs,
            p={prm.name: p[i] for i, prm in enumerate(self.parameters)},
            c={cap.name: c[i] for i, cap in enumerate(self.captures)},
            series_slots=series_slots,
        )
        self._environment(ctx)
        for e in self.effects:
            e.forces(ctx)
        total = ca.SX.zeros(3)
        for f in ctx.forces:
            total += f
        ctx.mass = ctx.mass + test.vehicle.mass
        ctx.q["mass"] = ca.SX(ctx.mass)  # a quantity even where it is constant
        ctx.q["specific_force"] = total / ctx.mass
        ctx.q["load_factor"] = ca.norm_2(ctx.q["specific_force"]) / G0
        ctx.xdot["position"] = xs["velocity"]
        ctx.xdot["velocity"] = ctx.q["specific_force"] + ca.vertcat(0.0, 0.0, -G0)
        ctx.state_vector, ctx.state_names = x, tuple(s.name for s in self.states)
        for e in self.effects:
            e.observations(ctx)
        for timing, _ in self.timings:
            if timing.crossing is not None:
                gap = ctx.expand_offsets(ctx.q[timing.crossing])
                xdot = ca.vertcat(*(ctx.xdot[n] for n in ctx.state_names))
                ctx.q[_rate_name(timing.crossing)] = (ca.jtimes(gap, x, xdot)
                                                      + ca.jacobian(gap, t))
        self.ctx = ctx
        self.constraints: list[Constraint] = [c_ for e in self.effects
                                              for c_ in e.constraints(ctx)]
        # (effect, channel, times, residuals in sigma) of every effect's pseudo-observations.
        self.penalties: list[tuple[str, str, np.ndarray, ca.SX]] = [
            (e.name, channel, np.asarray(times, dtype=float), ctx.expand_offsets(expr))
            for e in self.effects
            for channel, (times, expr) in e.penalties(ctx).items()]
        missing = [s.name for s in self.states if s.name not in ctx.xdot]
        if missing:
            raise ValueError(f"no effect defines the derivative of state(s) {missing}")

        # The series' knots (`ModelContext.time_series`), and in a model local in time the
        # slots' symbols after the parameters: their columns in the parameter vector.
        self.series = dict(ctx.series)
        slot_names = [n for n in ctx.p if n.startswith(SLOT_PREFIX)]
        p = ca.vertcat(p, *(ctx.p[n] for n in slot_names))
        first = len(self.parameters)
        self.slot_columns = {
            name: tuple(np.array([first + slot_names.index(f"{SLOT_PREFIX}{name}/{part}{j}")
                                  for j in range(series_slots)]) for part in "tv")
            for name in ctx.slots}
        args = [x, t, p, c]
        self.rhs = ca.Function("rhs", args, [ca.vertcat(*(ctx.xdot[s.name] for s in self.states))],
                               ["x", "t", "p", "c"], ["xdot"])
        self.sensor_channels = {name: tuple(ch) for name, ch in ctx.y.items()}
        # Each sensor's outputs as the effects wrote them: of (x, t, p, c) and the offset
        # states and times (`at_time_offset`), for the estimator's pieces; every function
        # below has the offsets' RK4 steps put in (`expand_offsets`).
        self.symbols = (x, t, p, c)
        self.offsets = tuple(ctx.offsets)
        self.output_expressions = {name: ca.vertcat(*ch.values()) for name, ch in ctx.y.items()}
        self.outputs = {
            name: ca.Function(f"y{i}", args, [ctx.expand_offsets(y)], ["x", "t", "p", "c"],
                              ["y"])
            for i, (name, y) in enumerate(self.output_expressions.items())
        }
        self.quantity_names = tuple(n for n, v in ctx.q.items()
                                    if isinstance(v, ca.SX) and v.numel() == 1)
        self.quantities = ca.Function("quantities", args, [ctx.expand_offsets(
            ca.vertcat(*(ctx.q[n] for n in self.quantity_names)))])
        self._capture_fns = {cap.name: ca.Function(f"capture{i}", args,
                                                   [ctx.expand_offsets(ctx.q[cap.quantity])])
                             for i, cap in enumerate(self.captures)}
        predicted = [_predicted_time(timing, event, ctx) for timing, event in self.timings]
        self.event_times = ca.Function("event_times", [p, c], [ca.vertcat(ca.SX(0, 1),
                                                                           *predicted)])

    def _observed_timings(self) -> list[tuple[EventTiming, Event]]:
        """The effects' event timings whose event the test observed, each with that event."""
        out = []
        for e in self.effects:
            for timing in e.event_timings(self.test):
                event = self.test.event(timing.event, timing.parachute, timing.stage)
                if event is not None:
                    out.append((timing, event))
        return out

    def _environment(self, ctx: ModelContext) -> None:
        """Air-relative velocity, density and dynamic pressure at the vehicle."""
        r, v = ctx.x["position"], ctx.x["velocity"]
        atm = self.test.atmosphere
        ctx.q["altitude"] = r[2]
        ctx.q["density"] = atm.density(r[2])
        ctx.set_air_relative_velocity(v - atm.wind(r[2]))

    # --- helpers for the estimator, the simulator and reports ---------------------------

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def parameter(self, name: str) -> Parameter:
        return next(p for p in self.parameters if p.name == name)

    def capture_function(self, name: str) -> ca.Function:
        return self._capture_fns[name]

    def state_scales(self) -> np.ndarray:
        return np.concatenate([np.full(s.size, s.scale) for s in self.states])

    def state_slice(self, name: str) -> slice:
        k = 0
        for s in self.states:
            if s.name == name:
                return slice(k, k + s.size)
            k += s.size
        raise KeyError(name)

    def parameter_vector(self, values: dict[str, float]) -> np.ndarray:
        """Full parameter vector from a dict, defaults where a value is absent."""
        return np.array([values.get(p.name, p.default) for p in self.parameters], dtype=float)

    def capture_vector(self, captured: dict[str, float]) -> np.ndarray:
        """The captured values in the model's order, from a dict by capture name."""
        return np.array([captured[c.name] for c in self.captures], dtype=float)

    def quantities_along(self, t: np.ndarray, x: np.ndarray, params: dict[str, float],
                         captured: dict[str, float]) -> dict[str, np.ndarray]:
        """Every scalar quantity at times `t` (s) and states `x` (one row per time)."""
        fn = self.quantities.map(len(t))
        values = np.asarray(fn(x.T, t, self.parameter_vector(params),
                               self.capture_vector(captured)))
        return dict(zip(self.quantity_names, values, strict=True))


# Floor of a crossing quantity's rate in the predicted time g/g' (units of g per s): keeps
# the prediction finite where a poor first guess has the quantity not yet rising.
RATE_FLOOR = 0.1


def timing_label(timing: EventTiming) -> str:
    """``main_bag_lift[pilot1]``: the event and the canopy (and stage) it belongs to."""
    index = (timing.parachute,) if timing.stage is None else (timing.parachute, timing.stage)
    return param_name(timing.event, *index)


def _rate_name(quantity: str) -> str:
    base, index = split_name(quantity)
    return param_name(f"{base}_rate", *index)


def _crossing_captures(timing: EventTiming, event: Event) -> list[Capture]:
    """A crossing quantity and its rate, captured at the observed time of the event."""
    if timing.crossing is None:
        return []
    label = timing_label(timing)
    return [Capture(f"gap@{label}", "", timing.crossing, "", at_time=event.time),
            Capture(f"gap_rate@{label}", "", _rate_name(timing.crossing), "",
                    at_time=event.time)]


def _predicted_time(timing: EventTiming, event: Event, ctx: ModelContext) -> ca.SX:
    """The model's time of an observed event (s), from parameters and captured values."""
    if timing.time is not None:
        predicted = ctx.q[timing.time]
        if ca.depends_on(predicted, ca.vertcat(ctx.t, *ctx.x.values())):
            raise ValueError(f"the predicted time {timing.time} of {timing_label(timing)} "
                             "must depend on parameters and captured values only; give a "
                             "state quantity as a crossing instead")
        return predicted
    label = timing_label(timing)
    rate = ctx.c[f"gap_rate@{label}"]
    rate = 0.5 * (rate + ca.sqrt(rate**2 + RATE_FLOOR**2))
    return event.time - ctx.c[f"gap@{label}"] / rate


def _unique_by_name(items: list[T], what: str) -> list[T]:
    seen: dict[str, T] = {}
    for it in items:
        if it.name in seen and seen[it.name] != it:
            raise ValueError(f"two effects declare {what} {it.name} differently")
        seen.setdefault(it.name, it)
    return list(seen.values())
