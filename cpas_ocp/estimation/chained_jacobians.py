"""Per-instance values and Jacobians built as chains of a few small compiled pieces.

Every continuity gap and every sensor residual of the NLP is one instance of a
small function of one or two node states, the parameters and the captures
(`transcription._Block`).  Expanded as one SX expression with its Jacobian,
such a function repeats the model once per RK4 step it takes: an interval of
four sub-steps is four copies of the step and of its derivative, and the
generated C grows with the sub-steps and with every effect the model holds.
On `drogue` the four-step gap's Jacobian was 1.7 MB of C (22 s at -O1) and
the model's native code 46 s of compiling in all.

Here the model is expanded once per *kind of piece* instead:

* `rk4_step` / `rk4_step_d`: one RK4 step x -> x(t + h) and, for `_d`, its
  Jacobians A = dx+/dx (state units), B = dx+/dp on the free parameters times
  their scales, C = dx+/dc times the captures' scale;
* `rhs` / `rhs_d`: the dynamics and their Jacobians the same way (for samples
  inside a long interval, predicted by Hermite interpolation);
* `observe_i` / `observe_i_d`: the outputs of sensor group i at a state and
  their Jacobians; where an output reads the state at another time (a sensor's
  lag, `ModelContext.at_time_offset`), that state and time are inputs of their
  own, and `offset_k` / `offset_k_d` give the offset dt(p) with its Jacobians.

Each block's function is then an MX chain of calls to these pieces, with the
chain rule written out (A_m ... A_1 for an interval of m sub-steps, the
parameters' sensitivities accumulated as D <- A D + B), evaluated in CasADi's
VM over native pieces.  An offset state is chained the same way, through
the step piece from the state at the sample, its step h = dt(p) / steps
carrying dt's sensitivities (the step piece also gives dx+/dh and dx+/dt).
Only the pieces are compiled, and their size does not grow with the
sub-steps or a lag's steps; the chains cost a few matrix products per
instance.  The lagged GPS output's Jacobian, expanded, was 5.5 MB of C.

A model local in time (`Model(..., series_slots=L)`: a wind process's knots
read through L slots) takes its slots' times and values as one more input
of every chain, `k` (per series, L times then L values), joined to the
parameter vector for the pieces; the slots' values are free columns of the
Jacobian like the parameters (`free_cols` indexes the joined vector).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from cpas_ocp.estimation.shooting_grid import hermite_state
from cpas_ocp.physics.integration import rk4
from cpas_ocp.physics.model import Model


@dataclass
class ModelPieces:
    """The model's compiled pieces (module docstring), by name, SX until `adopt` replaces
    them with native versions; `free_cols` the free parameters' indices in the parameter
    vector, `pscale` their scales, `cscale` the captures' scale, `xscale` the states'."""

    model: Model
    free_cols: list[int]
    pscale: np.ndarray
    cscale: float
    xscale: np.ndarray
    functions: dict[str, ca.Function] = field(default_factory=dict)
    # Per observation piece, the offsets (indices into `model.offsets`) its outputs read.
    offsets_of: dict[str, list[int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = self.model
        self._x, self._t, self._p, self._c = m.symbols
        # The slots' times and values after the parameters (a model local in time).
        self.n_slots = self._p.numel() - len(m.parameters)
        h = ca.SX.sym("h")
        self._add("rk4_step", [self._x, self._t, h, self._p, self._c],
                  rk4(m.rhs, self._x, self._t, h, self._p, self._c), [self._x, h, self._t])

    def _add(self, name: str, args: list[ca.SX], expr: ca.SX, wrt: Sequence[ca.SX]) -> None:
        """Piece `name` (value) and `name_d`: the value, its Jacobians in the free
        parameters (scaled) and the captures (scaled), then in each of `wrt`."""
        p, c = args[-2], args[-1]
        jp = ca.jacobian(expr, p)[:, self.free_cols] @ ca.diag(ca.DM(self.pscale)) \
            if self.free_cols else ca.SX(expr.numel(), 0)
        self.functions[name] = ca.Function(name, args, [expr])
        self.functions[f"{name}_d"] = ca.Function(
            f"{name}_d", args, [expr, jp, ca.jacobian(expr, c) * self.cscale,
                                *(ca.jacobian(expr, w) for w in wrt)])

    def need_rhs(self) -> None:
        """Add the dynamics' pieces (for samples inside long intervals)."""
        if "rhs" not in self.functions:
            self._add("rhs", [self._x, self._t, self._p, self._c],
                      self.model.rhs(self._x, self._t, self._p, self._c), [self._x])

    def add_observation(self, names: Sequence[str]) -> str:
        """Add the pieces of the outputs of sensors `names` (stacked), and of the offsets
        they read; the observation piece's name."""
        key = f"observe_{sum(n.startswith('observe_') for n in self.functions) // 2}"
        m = self.model
        y = ca.vertcat(*[m.output_expressions[name] for name in names])
        used = [k for k, o in enumerate(m.offsets)
                if ca.depends_on(y, ca.vertcat(o.x, o.t))]
        self.offsets_of[key] = used
        for k in used:
            if f"offset_{k}" not in self.functions:
                self._add(f"offset_{k}", [self._p, self._c], m.offsets[k].dt, [])
        at = [v for k in used for v in (m.offsets[k].x, m.offsets[k].t)]
        self._add(key, [self._x, self._t, *at, self._p, self._c], y, [self._x, *at])
        return key

    def adopt(self, functions: Sequence[ca.Function]) -> None:
        """Use `functions` (the same pieces, in `functions`' order: native code)."""
        self.functions = dict(zip(self.functions, functions, strict=True))

    # -- the chains --------------------------------------------------------------------

    def _pc(self) -> tuple[ca.MX, ca.MX, list[ca.MX], ca.MX]:
        """A chain's parameter and capture inputs, its slot input (none for a model global
        in time) and the parameter vector the pieces take (the parameters, then the
        slots)."""
        m = self.model
        p, c = ca.MX.sym("p", len(m.parameters)), ca.MX.sym("c", len(m.captures))
        if not self.n_slots:
            return p, c, [], p
        k = ca.MX.sym("k", self.n_slots)
        return p, c, [k], ca.vertcat(p, k)

    def _zeros(self, rows: int, n_states: int) -> list[ca.MX]:
        """Zero sensitivities of `rows` quantities to n_states states, p and c."""
        nx, nfree, ncap = self.model.nx, len(self.free_cols), len(self.model.captures)
        return [*(ca.MX(rows, nx) for _ in range(n_states)), ca.MX(rows, nfree),
                ca.MX(rows, ncap)]

    def _at_node(self, n_states: int) -> list[ca.MX]:
        """The sensitivities of the first node state argument itself: the state scales to
        itself, zero to the other state arguments, the parameters and c."""
        sens = self._zeros(self.model.nx, n_states)
        sens[0] = ca.MX(ca.diag(ca.DM(self.xscale)))
        return sens

    def _stepped(self, x: ca.MX, t: ca.MX, length: ca.MX, steps: int, p: ca.MX, c: ca.MX,
                 sens: list[ca.MX] | None, dlength: list[ca.MX] | None = None
                 ) -> tuple[ca.MX, list[ca.MX]]:
        """The state `steps` RK4 steps of length/steps after x at t, and (given `sens`, x's
        sensitivities to each state argument (scaled), the scaled free parameters and c)
        its own; `dlength`: those of `length` (None: it is data)."""
        h = length / steps
        if sens is None:
            for j in range(steps):
                x = self.functions["rk4_step"](x, t + j * h, h, p, c)
            return x, []
        for j in range(steps):
            x, b, cc, a, ah, at = self.functions["rk4_step_d"](x, t + j * h, h, p, c)
            new = [a @ d for d in sens]
            new[-2], new[-1] = new[-2] + b, new[-1] + cc
            if dlength is not None:  # the step's length and time move with the parameters
                new = [d + (ah + j * at) @ (dl / steps) for d, dl in zip(new, dlength,
                                                                         strict=True)]
            sens = new
        return x, sens

    def gap(self, steps: int) -> tuple[ca.Function, ca.Function]:
        """The continuity gap (x1 - x(t + dt)) / xscale of an interval of `steps` RK4 steps,
        as (values, values and Jacobian) with the inputs (x, x1, t, dt, p, c) and the
        Jacobian's columns (x, x1 scaled, free parameters scaled, c scaled), column-major."""
        nx = self.model.nx
        x, x1 = ca.MX.sym("x0", nx), ca.MX.sym("x1", nx)
        t, dt = ca.MX.sym("t"), ca.MX.sym("dt")
        p_in, c, k, p = self._pc()
        inv = ca.diag(ca.DM(1.0 / self.xscale))
        args = [x, x1, t, dt, p_in, c, *k]
        xe, _ = self._stepped(x, t, dt, steps, p, c, None)
        value = ca.Function(f"gap_{steps}_chain", args, [(x1 - xe) / self.xscale])
        xe, (dx, dp, dc) = self._stepped(x, t, dt, steps, p, c, self._at_node(1))
        jac = ca.horzcat(-inv @ dx, ca.DM.eye(nx), -inv @ dp, -inv @ dc)
        both = ca.Function(f"gap_{steps}_chain_jac", args, [(x1 - xe) / self.xscale, ca.vec(jac)])
        return value, both

    def residual(self, observe: str, kind: int) -> tuple[ca.Function, ca.Function]:
        """Weighted residuals (ym - y) / sg of sensor group `observe` as (values, values and
        Jacobian), with `transcription._sensor_blocks`' inputs for a sample `kind`: 0 at a
        node (x, t, ym, sg, p, c), 1 one partial step after it (x, t, dt, ym, sg, p, c), 2
        inside a long interval by Hermite interpolation (x, x1, t, dt, H, ym, sg, p, c)."""
        nx, n_out = self.model.nx, self.functions[observe].numel_out(0)
        ym, sg = ca.MX.sym("ym", n_out), ca.MX.sym("sg", n_out)
        p_in, c, k, p = self._pc()
        t, dt, length = ca.MX.sym("t"), ca.MX.sym("dt"), ca.MX.sym("H")
        states = [ca.MX.sym(f"x{i}", nx) for i in range(2 if kind == 2 else 1)]
        extra, t_at = ([], t) if kind == 0 else ([dt], t + dt) if kind == 1 else \
            ([dt, length], t + dt)
        args = [*states, t, *extra, ym, sg, p_in, c, *k]
        fns = []
        for jacobian in (False, True):
            x_at, sens = self._sample_state(kind, states, t, dt, length, p, c, jacobian)
            at, at_sens = self._offset_states(observe, x_at, t_at, p, c,
                                              sens if jacobian else None)
            if not jacobian:
                y = self.functions[observe](x_at, t_at, *at, p, c)
                fns.append(ca.Function(f"{observe}_{kind}_chain", args, [(ym - y) / sg]))
                continue
            y, yp, yc, yx, *y_at = self.functions[f"{observe}_d"](x_at, t_at, *at, p, c)
            jac = [yx @ d for d in sens]
            jac[-2], jac[-1] = jac[-2] + yp, jac[-1] + yc
            for y_o, d_o in zip(y_at, at_sens, strict=True):
                jac = [j + y_o @ d for j, d in zip(jac, d_o, strict=True)]
            jac = -ca.diag(1.0 / sg) @ ca.horzcat(*jac)
            fns.append(ca.Function(f"{observe}_{kind}_chain_jac", args,
                                   [(ym - y) / sg, ca.vec(jac)]))
        return fns[0], fns[1]

    def _offset_states(self, observe: str, x_at: ca.MX, t_at: ca.MX, p: ca.MX, c: ca.MX,
                       sens: list[ca.MX] | None) -> tuple[list[ca.MX], list[list[ca.MX]]]:
        """The offset states and times the outputs of `observe` read, as its piece takes
        them, and (given the sample state's `sens`) their sensitivities, in the same order."""
        at, at_sens = [], []
        for k in self.offsets_of[observe]:
            steps = self.model.offsets[k].steps
            if sens is None:
                length = self.functions[f"offset_{k}"](p, c)
                x_o, _ = self._stepped(x_at, t_at, length, steps, p, c, None)
                at += [x_o, t_at + length]
                continue
            length, lp, lc = self.functions[f"offset_{k}_d"](p, c)
            dlength = [*self._zeros(1, len(sens) - 2)[:-2], lp, lc]
            x_o, sens_o = self._stepped(x_at, t_at, length, steps, p, c, sens, dlength)
            at += [x_o, t_at + length]
            at_sens += [sens_o, dlength]
        return at, at_sens

    def _sample_state(self, kind: int, states: list[ca.MX], t: ca.MX, dt: ca.MX,
                      length: ca.MX, p: ca.MX, c: ca.MX, jacobian: bool
                      ) -> tuple[ca.MX, list[ca.MX]]:
        """The state at a sample of `kind` and (with `jacobian`) its sensitivities to each
        state argument (scaled), the scaled free parameters and c."""
        start = self._at_node(len(states))
        xs = start[0]
        if kind == 0:
            return states[0], (start if jacobian else [])
        if kind == 1:
            return self._stepped(states[0], t, dt, 1, p, c, start if jacobian else None)
        x_a, x_b = states
        if not jacobian:
            f_a = self.functions["rhs"](x_a, t, p, c)
            f_b = self.functions["rhs"](x_b, t + length, p, c)
            return hermite_state(x_a, x_b, f_a, f_b, length, dt), []
        f_a, fp_a, fc_a, fx_a = self.functions["rhs_d"](x_a, t, p, c)
        f_b, fp_b, fc_b, fx_b = self.functions["rhs_d"](x_b, t + length, p, c)
        zero = self._zeros(self.model.nx, 2)
        # The interpolant is linear in (x_a, f_a, x_b, f_b): each sensitivity is the
        # interpolant of theirs.
        sens = [hermite_state(xs, zero[0], fx_a @ xs, zero[0], length, dt),
                hermite_state(zero[1], xs, zero[1], fx_b @ xs, length, dt),
                hermite_state(zero[2], zero[2], fp_a, fp_b, length, dt),
                hermite_state(zero[3], zero[3], fc_a, fc_b, length, dt)]
        return hermite_state(x_a, x_b, f_a, f_b, length, dt), sens
