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
  their Jacobians.

Each block's function is then an MX chain of calls to these pieces, with the
chain rule written out (A_m ... A_1 for an interval of m sub-steps, the
parameters' sensitivities accumulated as D <- A D + B), evaluated in CasADi's
VM over native pieces.  Only the pieces are compiled, and their size does not
grow with the sub-steps; the chains cost a few matrix products per instance.
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

    def __post_init__(self) -> None:
        m = self.model
        self._x, self._t, self._h = ca.SX.sym("x", m.nx), ca.SX.sym("t"), ca.SX.sym("h")
        self._p = ca.SX.sym("p", len(m.parameters))
        self._c = ca.SX.sym("c", len(m.captures))
        self._add("rk4_step", [self._x, self._t, self._h, self._p, self._c],
                  rk4(m.rhs, self._x, self._t, self._h, self._p, self._c))

    def _add(self, name: str, args: list[ca.SX], expr: ca.SX) -> None:
        """Piece `name` (value) and `name_d` (value and Jacobians in x, free p, c)."""
        x, p, c = args[0], args[-2], args[-1]
        jp = ca.jacobian(expr, p)[:, self.free_cols] @ ca.diag(ca.DM(self.pscale)) \
            if self.free_cols else ca.SX(expr.numel(), 0)
        self.functions[name] = ca.Function(name, args, [expr])
        self.functions[f"{name}_d"] = ca.Function(
            f"{name}_d", args, [expr, ca.jacobian(expr, x), jp, ca.jacobian(expr, c) * self.cscale])

    def need_rhs(self) -> None:
        """Add the dynamics' pieces (for samples inside long intervals)."""
        if "rhs" not in self.functions:
            self._add("rhs", [self._x, self._t, self._p, self._c],
                      self.model.rhs(self._x, self._t, self._p, self._c))

    def add_observation(self, names: Sequence[str]) -> str:
        """Add the pieces of the outputs of sensors `names` (stacked); their name."""
        key = f"observe_{sum(n.startswith('observe_') for n in self.functions) // 2}"
        m = self.model
        y = ca.vertcat(*[m.outputs[name](self._x, self._t, self._p, self._c) for name in names])
        self._add(key, [self._x, self._t, self._p, self._c], y)
        return key

    def adopt(self, functions: Sequence[ca.Function]) -> None:
        """Use `functions` (the same pieces, in `functions`' order: native code)."""
        self.functions = dict(zip(self.functions, functions, strict=True))

    # -- the chains --------------------------------------------------------------------

    def _states(self, n_states: int) -> tuple[list[ca.MX], ca.DM]:
        nx = self.model.nx
        return [ca.MX.sym(f"x{i}", nx) for i in range(n_states)], ca.diag(ca.DM(self.xscale))

    def _pc(self) -> tuple[ca.MX, ca.MX]:
        m = self.model
        return ca.MX.sym("p", len(m.parameters)), ca.MX.sym("c", len(m.captures))

    def _stepped(self, x: ca.MX, t: ca.MX, length: ca.MX, steps: int, p: ca.MX, c: ca.MX,
                 jacobian: bool) -> tuple[ca.MX, list[ca.MX]]:
        """The state `steps` RK4 steps of length/steps after x at t, and (with `jacobian`)
        its sensitivities to the scaled x, the scaled free parameters and c."""
        h = length / steps
        if not jacobian:
            for j in range(steps):
                x = self.functions["rk4_step"](x, t + j * h, h, p, c)
            return x, []
        _, xs = self._states(0)
        dx = dp = dc = None
        for j in range(steps):
            x, a, b, cc = self.functions["rk4_step_d"](x, t + j * h, h, p, c)
            if dx is None:
                dx, dp, dc = a @ xs, b, cc
            else:
                dx, dp, dc = a @ dx, a @ dp + b, a @ dc + cc
        return x, [dx, dp, dc]

    def gap(self, steps: int) -> tuple[ca.Function, ca.Function]:
        """The continuity gap (x1 - x(t + dt)) / xscale of an interval of `steps` RK4 steps,
        as (values, values and Jacobian) with the inputs (x, x1, t, dt, p, c) and the
        Jacobian's columns (x, x1 scaled, free parameters scaled, c scaled), column-major."""
        (x, x1), _ = self._states(2)
        t, dt = ca.MX.sym("t"), ca.MX.sym("dt")
        p, c = self._pc()
        inv = ca.diag(ca.DM(1.0 / self.xscale))
        args = [x, x1, t, dt, p, c]
        xe, _ = self._stepped(x, t, dt, steps, p, c, jacobian=False)
        value = ca.Function(f"gap_{steps}_chain", args, [(x1 - xe) / self.xscale])
        xe, (dx, dp, dc) = self._stepped(x, t, dt, steps, p, c, jacobian=True)
        jac = ca.horzcat(-inv @ dx, ca.DM.eye(self.model.nx), -inv @ dp, -inv @ dc)
        both = ca.Function(f"gap_{steps}_chain_jac", args, [(x1 - xe) / self.xscale, ca.vec(jac)])
        return value, both

    def residual(self, observe: str, kind: int) -> tuple[ca.Function, ca.Function]:
        """Weighted residuals (ym - y) / sg of sensor group `observe` as (values, values and
        Jacobian), with `transcription._sensor_blocks`' inputs for a sample `kind`: 0 at a
        node (x, t, ym, sg, p, c), 1 one partial step after it (x, t, dt, ym, sg, p, c), 2
        inside a long interval by Hermite interpolation (x, x1, t, dt, H, ym, sg, p, c)."""
        n_out = self.functions[observe].numel_out(0)
        ym, sg = ca.MX.sym("ym", n_out), ca.MX.sym("sg", n_out)
        p, c = self._pc()
        t, dt, length = ca.MX.sym("t"), ca.MX.sym("dt"), ca.MX.sym("H")
        states, _ = self._states(2 if kind == 2 else 1)
        if kind == 0:
            extra, t_at = [], t
        elif kind == 1:
            extra, t_at = [dt], t + dt
        else:
            extra, t_at = [dt, length], t + dt
        args = [*states, t, *extra, ym, sg, p, c]
        fns = []
        for jacobian in (False, True):
            x_at, sens = self._sample_state(kind, states, t, dt, length, p, c, jacobian)
            if not jacobian:
                y = self.functions[observe](x_at, t_at, p, c)
                fns.append(ca.Function(f"{observe}_{kind}_chain", args, [(ym - y) / sg]))
                continue
            y, yx, yp, yc = self.functions[f"{observe}_d"](x_at, t_at, p, c)
            *dstates, dp, dc = sens
            weight = -ca.diag(1.0 / sg)
            jac = weight @ ca.horzcat(*(yx @ d for d in dstates), yx @ dp + yp, yx @ dc + yc)
            fns.append(ca.Function(f"{observe}_{kind}_chain_jac", args,
                                   [(ym - y) / sg, ca.vec(jac)]))
        return fns[0], fns[1]

    def _sample_state(self, kind: int, states: list[ca.MX], t: ca.MX, dt: ca.MX,
                      length: ca.MX, p: ca.MX, c: ca.MX, jacobian: bool
                      ) -> tuple[ca.MX, list[ca.MX]]:
        """The state at a sample of `kind` and (with `jacobian`) its sensitivities to each
        state argument (scaled), the scaled free parameters and c."""
        nx, nfree, ncap = self.model.nx, len(self.free_cols), len(self.model.captures)
        _, xs = self._states(0)
        if kind == 0:
            return states[0], ([xs, ca.MX(nx, nfree), ca.MX(nx, ncap)] if jacobian else [])
        if kind == 1:
            return self._stepped(states[0], t, dt, 1, p, c, jacobian)
        x_a, x_b = states
        if not jacobian:
            f_a = self.functions["rhs"](x_a, t, p, c)
            f_b = self.functions["rhs"](x_b, t + length, p, c)
            return hermite_state(x_a, x_b, f_a, f_b, length, dt), []
        f_a, fx_a, fp_a, fc_a = self.functions["rhs_d"](x_a, t, p, c)
        f_b, fx_b, fp_b, fc_b = self.functions["rhs_d"](x_b, t + length, p, c)
        zero_x = ca.MX(nx, nx)
        # The interpolant is linear in (x_a, f_a, x_b, f_b): each sensitivity is the
        # interpolant of theirs.
        sens = [hermite_state(xs, zero_x, fx_a @ xs, zero_x, length, dt),
                hermite_state(zero_x, xs, zero_x, fx_b @ xs, length, dt),
                hermite_state(ca.MX(nx, nfree), ca.MX(nx, nfree), fp_a, fp_b, length, dt),
                hermite_state(ca.MX(nx, ncap), ca.MX(nx, ncap), fc_a, fc_b, length, dt)]
        return hermite_state(x_a, x_b, f_a, f_b, length, dt), sens
