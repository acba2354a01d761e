"""The symbolic workspace a model is built in: the effects read the test, the time, the
states, parameters and captured values from it and write their quantities, forces,
state derivatives and sensor outputs into it (`effects.base.Effect`), in two passes
(`model.Model`).  States at another time (a sensor's lag) are symbols of their own
(`TimeOffset`), put in by `expand_offsets`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.integration import rk4

SLOT_PREFIX = "@slot:"  # names of a local model's series slots in `ModelContext.p`


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
    # Series of parameter knots in time (`time_series`): name -> (knot times (s), the
    # knots' parameter names).  With `series_slots` (a model local in time), each series
    # reads that many consecutive knots through symbols of their own, (times, values),
    # appended to `p` (named SLOT_PREFIX + series + "/t" or "/v" and the slot).
    series: dict[str, tuple[np.ndarray, tuple[str, ...]]] = field(default_factory=dict)
    series_slots: int = 0
    slots: dict[str, tuple[ca.SX, ca.SX]] = field(default_factory=dict)

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

    def time_series(self, name: str, times: np.ndarray, names: Sequence[str],
                    spacing: float) -> ca.SX:
        """A quantity piecewise linear in time through knots at `times` (s, `spacing` apart)
        whose values are the parameters `names`, constant beyond the first and last knot:
        the knots' hat functions, max(0, 1 - |t - t_k| / spacing), times their values,
        summed.  A knot acts only within `spacing` of its time.

        In a model local in time (`series_slots` L > 0) the sum runs over L slots of
        consecutive knots instead, each a time and a value symbol of its own (appended to
        `p`): the estimator gives every shooting interval and sample the knots around it,
        so that its functions do not grow with the number of knots, nor its Jacobians
        with a column per knot."""
        times = np.asarray(times, dtype=float)
        self.series[name] = (times, tuple(names))
        t = ca.fmin(ca.fmax(self.t, times[0]), times[-1])
        if self.series_slots:
            if name not in self.slots:
                self.slots[name] = (ca.SX.sym(f"{name}_t", self.series_slots),
                                    ca.SX.sym(f"{name}_v", self.series_slots))
                for j in range(self.series_slots):
                    for part, sym in zip("tv", self.slots[name], strict=True):
                        self.p[f"{SLOT_PREFIX}{name}/{part}{j}"] = sym[j]
            tau, value = self.slots[name]
            terms = [(tau[j], value[j]) for j in range(self.series_slots)]
        else:
            terms = [(float(tk), self.p[n]) for tk, n in zip(times, names, strict=True)]
        u = ca.SX(0.0)
        for tk, v in terms:
            u = u + ca.fmax(0.0, 1.0 - ca.fabs(t - tk) / spacing) * v
        return u

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
