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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeVar

import casadi as ca
import numpy as np

from cpas_ocp.physics.effects.base import Capture, Constraint, Effect, EventTiming, State
from cpas_ocp.physics.integration import rk4
from cpas_ocp.physics.parameters import Parameter, param_name, split_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.io.flight_test import Event, FlightTest

T = TypeVar("T", Parameter, State, Capture)

CORE_STATES = (
    State("position", 3, "m", 1000.0),
    State("velocity", 3, "m/s", 100.0),
)


@dataclass
class ModelContext:
    """The symbolic workspace effects read from and write into."""

    test: FlightTest
    t: ca.SX
    x: dict[str, ca.SX]
    p: dict[str, ca.SX]
    c: dict[str, ca.SX]
    q: dict[str, ca.SX] = field(default_factory=dict)
    xdot: dict[str, ca.SX] = field(default_factory=dict)
    forces: list[ca.SX] = field(default_factory=list)
    mass: ca.SX | float = 0.0
    y: dict[str, dict[str, ca.SX]] = field(default_factory=dict)
    state_vector: ca.SX | None = None
    state_names: tuple[str, ...] = ()
    # Canopies that are bodies of their own (elastic risers); the others ride on the vehicle.
    separate_bodies: set[str] = field(default_factory=set)
    offsets: list[TimeOffset] = field(default_factory=list)  # `at_time_offset`'s
    # The offsets' symbols and their RK4 steps, once formed (`expand_offsets`).
    _expansion: tuple[ca.SX, ca.SX] | None = field(default=None, repr=False)

    def separate_body(self, chute: str, effect: str) -> None:
        """Make canopy `chute` a body of its own (on behalf of riser model `effect`).

        Its air mass then belongs to that body, so the `added_mass` effect must
        come later in the list: it must not yet have lumped the air onto the vehicle.
        """
        if f"added_mass[{chute}]" in self.q:
            raise ValueError(f"list the added_mass effect after {effect}: the canopy's air "
                             f"mass belongs to the canopy's own body")
        self.separate_bodies.add(chute)

    def scale(self, name: str, factor: ca.SX | float) -> None:
        """Multiply quantity `name` (1 if not yet set) by `factor`."""
        self.q[name] = self.q.get(name, 1.0) * factor

    def scale_drag(self, chute: str, factor: ca.SX | float, effect: str,
                   users: tuple[str, ...]) -> None:
        """Multiply canopy `chute`'s ``drag[P]`` by `factor` on behalf of `effect`.

        The drag must already exist (the `canopy_inflation` effect writes it) and
        none of the quantities `users` (``<quantity>[P]`` of the effects that
        consume the drag) may yet: the order of the effect list is checked, not
        assumed.
        """
        drag = f"drag[{chute}]"
        if drag not in self.q:
            raise ValueError(f"list the {effect} effect after canopy_inflation: it changes "
                             f"the canopy's drag")
        early = [u for u in users if f"{u}[{chute}]" in self.q]
        if early:
            raise ValueError(f"list the {effect} effect before the effects that write "
                             f"{', '.join(early)}: they use the canopy's drag")
        self.scale(drag, factor)

    def set_air_relative_velocity(self, v_air: ca.SX) -> None:
        """The vehicle's velocity relative to the air (m/s, east-north-up), and from it the
        airspeed, the dynamic pressure 0.5 rho V^2 (Pa) and the drag direction."""
        airspeed = ca.sqrt(ca.sumsqr(v_air) + 1e-6)
        self.q["air_relative_velocity"] = v_air
        self.q["airspeed"] = airspeed
        self.q["dynamic_pressure"] = 0.5 * self.q["density"] * airspeed**2
        self.q["drag_direction"] = -v_air / airspeed

    def add_air_velocity(self, u: ca.SX, effect: str) -> None:
        """Move the air at the vehicle by `u` (m/s, east-north-up) on top of the
        atmosphere's wind, on behalf of `effect` (a gust process, a wind profile): the
        airspeed, dynamic pressure and drag direction follow.  Only before any effect forms
        drag, which would otherwise have used the air before the move: the order of the
        effect list is checked, not assumed."""
        early = [q for q in self.q if q.split("[")[0] in ("drag", "cds")]
        if early:
            raise ValueError(f"list the {effect} effect before the effects that form drag: "
                             f"{', '.join(early)} already use the air before it")
        self.set_air_relative_velocity(self.q["air_relative_velocity"] - u)

    def at_time_offset(self, expr: ca.SX, dt: ca.SX | float, steps: int) -> ca.SX:
        """`expr` (a function of state and time) evaluated at t + dt instead of t.

        The state at t + dt comes from `steps` RK4 steps of the dynamics
        from the state at t (backwards for dt < 0); parameters and captured
        values are unchanged.  Available in the second pass, when every state
        derivative is known.  A sensor that reports with a time lag tau sees
        ``at_time_offset(y, -tau, n)``; the step dt/steps should stay well
        below the time scale of the dynamics (inflation: about 0.1 s).

        The expression returned holds the offset state and time as symbols of
        their own (`TimeOffset`); `Model` puts the RK4 steps in for them in
        every function it gives (`expand_offsets`), and the estimator's pieces
        chain them through one compiled step instead (`chained_jacobians`).
        """
        if self.state_vector is None:
            raise RuntimeError("at_time_offset is available in the observations pass only")
        xdot = ca.vertcat(*(self.xdot[n] for n in self.state_names))
        # An offset inside `expr` (a lag on an output that already reads another time) is
        # put in first, so that it moves with the state it is taken from.
        expr = self.expand_offsets(expr)
        k = len(self.offsets)
        offset = TimeOffset(ca.SX.sym(f"x_offset{k}", self.state_vector.numel()),
                            ca.SX.sym(f"t_offset{k}"), ca.SX(dt), steps,
                            ca.Function("dynamics", [self.state_vector, self.t,
                                                     *self._parameters()], [xdot]))
        self.offsets.append(offset)
        self._expansion = None
        return ca.substitute(expr, ca.vertcat(self.state_vector, self.t),
                             ca.vertcat(offset.x, offset.t))

    def expand_offsets(self, expr: ca.SX) -> ca.SX:
        """`expr` with every offset state and time (`at_time_offset`) replaced by its RK4
        steps from the state at t: a function of (x, t, p, c) alone."""
        if not self.offsets:
            return expr
        if self._expansion is None:  # the steps, formed once for every expression
            p, c = self._parameters()
            symbols, values = [], []
            for o in self.offsets:
                x, t, h = self.state_vector, self.t, o.dt / o.steps
                for _ in range(o.steps):
                    x, t = rk4(o.dynamics, x, t, h, p, c), t + h
                symbols += [o.x, o.t]
                values += [x, t]
            self._expansion = (ca.vertcat(*symbols), ca.vertcat(*values))
        return ca.substitute(expr, *self._expansion)

    def _parameters(self) -> tuple[ca.SX, ca.SX]:
        """The parameter and captured-value vectors, as the dynamics take them."""
        return (ca.vertcat(ca.SX(0, 1), *self.p.values()),
                ca.vertcat(ca.SX(0, 1), *self.c.values()))


@dataclass
class TimeOffset:
    """A state `x` and time `t` standing for those `dt` (s, an expression of the
    parameters) after the state and time of the model, `steps` RK4 steps of `dynamics`
    away (`ModelContext.at_time_offset`)."""

    x: ca.SX
    t: ca.SX
    dt: ca.SX
    steps: int
    dynamics: ca.Function


class Model:
    """Dynamics x' = f(x, t, p, c) and sensor outputs y = h(x, t, p, c) of one test phase."""

    def __init__(self, test: FlightTest, effects: Sequence[Effect]) -> None:
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
