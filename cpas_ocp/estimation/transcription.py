"""The transcription: one test phase as one multiple-shooting NLP (see `estimator`).

The grid, the decision variables and their scaling and bounds, the continuity gaps,
the sensors' weighted residuals, the captures, the effects' constraints, what-if
limits, priors and pseudo-observations, and the functions Ipopt and the linearisation
evaluate (the points a solve starts from are `starting_points`').
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import casadi as ca
import numpy as np

from cpas_ocp.estimation.action_windows import ActionWindows
from cpas_ocp.estimation.chained_jacobians import ModelPieces
from cpas_ocp.estimation.compiled import in_background, native_build
from cpas_ocp.estimation.fit import (
    EVENTS,
    PRIORS,
    Fit,
    SensorResidual,
    Settings,
    SolverStats,
    default_grid_step,
)
from cpas_ocp.estimation.kinematic_track import guessed_states
from cpas_ocp.estimation.nlp_functions import MarquardtDamping, PointEvaluations, bound_violations
from cpas_ocp.estimation.reduction import initial_guess
from cpas_ocp.estimation.series_slots import SeriesSlots, offset_reach, series_slots
from cpas_ocp.estimation.shooting_grid import (
    ShootingGrid,
    TimeWindow,
    dynamics_grid,
    hermite_state,
    stable_refinement,
    substeps_of,
)
from cpas_ocp.estimation.simulate import rk4_step
from cpas_ocp.estimation.sparse_rows import Rows, stacked_parts
from cpas_ocp.io.model_spec import ModelSpec, spec_from_effects, spec_of_test, unfitted_sensors
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import CORE_STATES, Model, timing_label


@dataclass
class _Nlp:
    """The NLP while it is transcribed (`Transcription._build`): the decision
    variables X (node states), P (free parameters) and C (captured values), all scaled;
    their physical values Xp, Cp and pfull (every parameter, the fixed ones as constants);
    the whole decision vector z; the scales; the SX symbols of one instance (x, x1, t, dt,
    p, c) and one interval's RK4 end state xe; and the constraint pieces g with their
    bounds, the residual pieces, and the capture constraints whose curvature the Hessian
    carries (`curved`; `n_small` constraint pieces in all, `knots`: process knots held in
    that curvature)."""

    X: ca.MX
    P: ca.MX
    C: ca.MX
    Xp: ca.MX
    Cp: ca.MX
    pfull: ca.MX
    z: ca.MX
    free_index: dict[str, int]
    xscale: np.ndarray
    cscale: float
    syms: dict[str, ca.SX]
    xe: ca.SX
    g: list = field(default_factory=list)
    lbg: list = field(default_factory=list)
    ubg: list = field(default_factory=list)
    residuals: list = field(default_factory=list)
    curved: list = field(default_factory=list)
    n_small: int = 0
    knots: bool = False
    P_held: ca.MX = field(init=False)

    def __post_init__(self) -> None:
        self.P_held = ca.MX.sym("P_held", self.P.numel())


@dataclass
class _Block:
    """A per-instance function, its instances' node indices, times and data columns.

    `times` are the times of the first node of each instance: a sample between
    nodes is predicted from the node before it at `times`, a partial step of
    length dt later (dt is a data column).
    """

    fn: ca.Function
    nodes: list[np.ndarray]
    times: np.ndarray
    data: list[np.ndarray]
    chain: tuple[str, int] = ("", 0)  # ("gap", RK4 steps) or (observation piece, kind)
    # Per instance, the shooting interval it lies in, where its chain reads the knots of a
    # model local in time (`series_slots`); None where it takes the whole parameter vector.
    interval: np.ndarray | None = None


@dataclass
class _Piece:
    """A stretch of the residual or constraint vector, four ways: `symbolic` through CasADi's
    VM (differentiable: the exact Hessian's graph), `value` for trial points (native
    code where compiled), `with_jacobian` the same values from the Jacobian function,
    and `jacobian` w.r.t. the scaled decision vector; and the time of each row (an
    instance's first node), for `ActionWindows`."""

    symbolic: ca.MX
    value: ca.MX
    with_jacobian: ca.MX
    jacobian: ca.MX
    times: np.ndarray  # per row, the time (s) it belongs to; NaN where none
    # Where the Jacobian's rows are rows of other pieces' (`_gathered`), those rows, so that
    # the point functions gather them once from where they come (`sparse_rows`).
    rows_of: Rows | None = None

    @classmethod
    def of(cls, expr: ca.MX, z: ca.MX) -> _Piece:
        """A small expression: one graph for its values, CasADi's Jacobian for the rest (its
        rows belong to no time)."""
        return cls(expr, expr, expr, ca.jacobian(expr, z), np.full(expr.numel(), np.nan))


def _stack(pieces: Sequence[_Piece], field_name: str) -> ca.MX:
    """One field of every piece, stacked."""
    return ca.vertcat(*[getattr(p, field_name) for p in pieces])


def _stacked_jacobian(pieces: Sequence[_Piece]) -> ca.MX:
    """The Jacobians of every piece, stacked through one gather of nonzeros
    (`sparse_rows.stacked_parts`)."""
    return stacked_parts([p.jacobian if p.rows_of is None else p.rows_of for p in pieces])


def _gathered(pieces: Sequence[_Piece], destinations: Sequence[np.ndarray],
              offsets: Sequence[int]) -> list[_Piece]:
    """Row i of `pieces[b]` moved to row `destinations[b][i]` of the stacked result (the
    destinations cover 0..offsets[-1]-1 once), cut into one piece per range
    offsets[j]..offsets[j+1]."""
    if not pieces:
        return []
    order = np.argsort(np.concatenate(destinations))  # stacked row of each result row
    stacked = [_stack(pieces, f) for f in ("symbolic", "value", "with_jacobian")]
    times = _stack_times(pieces)
    mats = tuple(p.jacobian for p in pieces)
    jacobian = ca.vertcat(*mats)  # for the symbolic graph; the point functions gather
    out = []
    for a, b in itertools.pairwise(offsets):
        rows = order[a:b].tolist()
        out.append(_Piece(*(x[rows] for x in stacked), jacobian[rows, :], times[order[a:b]],
                          Rows(mats, order[a:b])))
    return out


def _stack_times(pieces: Sequence[_Piece]) -> np.ndarray:
    """The row times of every piece, stacked."""
    return np.concatenate([p.times for p in pieces]) if pieces else np.zeros(0)


class PointFunctions(NamedTuple):
    """The four functions of the scaled decision vector z that `PointEvaluations` evaluates
    (VM graphs, or chains of native pieces once they are compiled)."""

    residual_value: ca.Function  # z -> r, the weighted residuals
    residual_jacobian: ca.Function  # z -> (r, dr/dz)
    constraint_value: ca.Function  # z -> g
    constraints: ca.Function  # z -> (g, dg/dz)


def cubic_bspline(u: ca.MX) -> ca.MX:
    """Cubic B-spline kernel (support |u| < 2, C2, a partition of unity on integer nodes)."""
    a = ca.fabs(u)
    return ca.if_else(a < 1.0, (4.0 - 6.0 * a**2 + 3.0 * a**3) / 6.0,
                      ca.if_else(a < 2.0, (2.0 - a) ** 3 / 6.0, 0.0))


class Transcription:
    """The NLP of one test phase, built once (`Estimator`'s first part): its variables,
    constraints, residuals and bounds, and the functions evaluated on it."""

    def __init__(self, test: FlightTest, effects: Sequence[Effect] | ModelSpec | None = None,
                 settings: Settings | None = None) -> None:
        """`effects`: an effect list, a `ModelSpec`, or None for the model the manifest declares.

        `settings.free` and `settings.fixed` override the spec's choice.
        """
        self.test = test
        self.settings = settings or Settings()
        if effects is None:
            self.spec = spec_of_test(test)
        elif isinstance(effects, ModelSpec):
            self.spec = effects
        else:
            self.spec = spec_from_effects(effects)
        self.model = self.spec.model(test)
        self.unfitted = unfitted_sensors(test, self.model)
        m, s = self.model, self.settings
        names = m.parameter_names
        if s.free is None:
            self.free = self.spec.free_names(m)
        else:
            unknown = sorted(set(s.free) - set(names))
            if unknown:
                raise ValueError(f"cannot estimate unknown parameters {unknown}")
            self.free = list(s.free)
        fixed = {**self.spec.fixed_values(m), **s.fixed}
        given = {**s.guess, **fixed}
        if set(names) <= set(given):
            # Every value given (a model started from another's fit): no reduction, which
            # took 1.3 s of each 4 s score test on `drogue`.
            self.guess = {n: given[n] for n in names}
        else:
            self.guess = initial_guess(test, m, fixed)
            self.guess.update(s.guess)
        self.values = {**self.guess, **fixed}

        if s.nodes is not None:
            nodes = np.asarray(s.nodes, dtype=float)
            grid = ShootingGrid(nodes, substeps_of(nodes) if s.interval_steps is None
                                else np.asarray(s.interval_steps, dtype=int))
            if grid.steps.shape != (len(nodes) - 1,):
                raise ValueError(f"{grid.steps.size} intervals' sub-steps for "
                                 f"{len(nodes) - 1} intervals")
            if len(m.states) > len(CORE_STATES):  # an effect's states: maybe a fast mode
                grid = self._stable_grid(grid)
        elif s.grid_step is not None:
            n = int(np.floor((test.t_end - test.t_start) / s.grid_step + 1e-9))
            nodes = test.t_start + s.grid_step * np.arange(n + 1)
            grid = ShootingGrid(nodes, substeps_of(nodes))
        else:
            grid = self._dynamics_grid(default_grid_step(test))
        self.t, self.steps = grid.nodes, grid.steps
        self.settings = replace(s, nodes=tuple(self.t),
                                interval_steps=tuple(int(k) for k in self.steps))
        # The finest interval, rounded to the microsecond: the B-spline's spacing.
        self.fine_step = float(np.round(np.min(np.diff(self.t)), 6))
        self._build(len(self.t) - 1, self.fine_step)

    def _stable_grid(self, grid: ShootingGrid) -> ShootingGrid:
        """A given grid, refined where this model's own states need finer steps for RK4 to
        stay stable (`shooting_grid.stable_refinement`)."""
        fine_step = float(np.round(np.min(np.diff(grid.nodes)), 6))
        return stable_refinement(grid, self.model, self.values, self._first_state(fine_step),
                                 fine_step)

    def _dynamics_grid(self, fine_step: float) -> ShootingGrid:
        """The grid chosen from the model's dynamics at the first guesses (`shooting_grid`)."""
        m, test = self.model, self.test
        windows = []
        for cap in m.captures:
            if cap.at_time is not None:
                windows.append(TimeWindow(cap.at_time, cap.at_time, cap.at_time))
                continue
            prm, value = m.parameter(cap.time_parameter), self.values[cap.time_parameter]
            windows.append(TimeWindow(prm.lower, prm.upper, value) if prm.name in self.free
                           else TimeWindow(value, value, value))
        return dynamics_grid(m, self.values, self._first_state(fine_step), test.t_start,
                             test.t_end, fine_step, windows)

    def _first_state(self, fine_step: float) -> np.ndarray:
        """The guessed state at the phase's start (`kinematic_track.guessed_states`; the
        effects' guesses take a rate from the first two lattice points)."""
        t0 = self.test.t_start
        return guessed_states(self.test, self.model, self.values,
                              np.array([t0, t0 + fine_step]))[0][:, 0]

    # ------------------------------------------------------------------ transcription
    def _build(self, n: int, h: float) -> None:
        """The NLP on the grid `self.t` of n intervals, the finest h long (s): its
        variables, the continuity gaps and sensor residuals, the captures, the effects'
        constraints, what-if limits, observed event times, priors and pseudo-observations,
        then the functions evaluated on it and its variables' bounds."""
        nlp = self._variables(n)
        self._gaps_and_sensors(nlp, n, h)
        self._captures(nlp, h)
        self._effect_constraints(nlp)
        self._limits(nlp, n)
        self._extra_residuals(nlp)
        self._assemble(nlp, n)
        self._variable_bounds(nlp)

    def _variables(self, n: int) -> _Nlp:
        """The decision variables (node states X, free parameters P, captured values C, all
        scaled to order one), their physical values, and the RK4 step of one interval."""
        m = self.model
        nx, ncap = m.nx, len(m.captures)
        xscale = m.state_scales()
        self.pscale = np.array([m.parameter(f).scale for f in self.free])
        X = ca.MX.sym("X", nx, n + 1)
        P = ca.MX.sym("P", len(self.free))
        C = ca.MX.sym("C", ncap)
        cscale = 100.0
        Xp = ca.repmat(ca.DM(xscale), 1, n + 1) * X
        Cp = cscale * C
        free_index = {f: i for i, f in enumerate(self.free)}
        pfull = ca.vertcat(*[
            P[free_index[p.name]] * self.pscale[free_index[p.name]] if p.name in free_index
            else ca.MX(self.values.get(p.name, p.default)) for p in m.parameters])
        self.step = rk4_step(m)
        syms = {"x": ca.SX.sym("x", nx), "x1": ca.SX.sym("x1", nx), "t": ca.SX.sym("t"),
                "dt": ca.SX.sym("dt"), "p": ca.SX.sym("p", len(m.parameters)),
                "c": ca.SX.sym("c", ncap)}
        xe = self._interval_end(syms["x"], syms["t"], syms["dt"], syms["p"], syms["c"], 1)
        self._ctx = (X, Xp, pfull, Cp, xscale, cscale)
        return _Nlp(X, P, C, Xp, Cp, pfull, ca.vertcat(ca.vec(X), P, C), free_index, xscale,
                    cscale, syms, xe)

    def _interval_end(self, x: ca.SX, t: ca.SX, dt: ca.SX, p: ca.SX, c: ca.SX,
                      substeps: int) -> ca.SX:
        """The state one shooting interval of length dt (s) after `x` at `t`: `substeps`
        (the interval's, `self.steps`) times `settings.substeps` RK4 steps."""
        m = substeps * self.settings.substeps
        for j in range(m):
            x = self.step(x, t + j * dt / m, dt / m, p, c)
        return x

    def _gaps_and_sensors(self, nlp: _Nlp, n: int, h: float) -> None:
        """The continuity gap of every shooting interval and the weighted residuals of every
        sample of every sensor, each a per-instance function mapped over its instances
        with its Jacobian (sensors sampled between nodes are predicted one partial RK4
        step after the node before the sample)."""
        y = nlp.syms
        counts = self.steps
        pieces = self._model_pieces()
        local = self.slots is not None
        if counts.max() > 1:  # long intervals: samples inside them need the dynamics
            pieces.need_rhs()
        blocks, gap_rows = [], []
        # One gap function per number of sub-steps; the gaps' rows stay node-major.
        for m in np.unique(counts):
            ks = np.flatnonzero(counts == m)
            xe = nlp.xe if m == 1 else self._interval_end(y["x"], y["t"], y["dt"], y["p"],
                                                          y["c"], int(m))
            gap = ca.Function("gap" if m == 1 else f"gap_{m}",
                              [y["x"], y["x1"], y["t"], y["dt"], y["p"], y["c"]],
                              [(y["x1"] - xe) / nlp.xscale])
            blocks.append(_Block(gap, [ks, ks + 1], self.t[ks], [np.diff(self.t)[ks]],
                                 ("gap", int(m) * self.settings.substeps),
                                 ks if local else None))
            gap_rows.append((ks[:, None] * self.model.nx
                             + np.arange(self.model.nx)[None, :]).ravel())
        n_gap_blocks = len(blocks)
        sensor_blocks, destinations, offsets = self._sensor_blocks(self.step, n, h, pieces)
        blocks += sensor_blocks
        # Each block's values (the line search's trial points) and its values with the
        # Jacobian (accepted points) are chains of the model's few pieces, which run as
        # native code once compiled (`chained_jacobians`; until then, and without a
        # compiler, in CasADi's VM: `_switch_to_native`); the block functions themselves
        # stay in the VM, for the differentiable graph (`_obj`, `_g`).
        build = None
        if self.settings.compile:
            build = native_build(list(pieces.functions.values()))
            if build is not None and not in_background():
                pieces.adopt(build.wait())
                build = None
            elif build is not None and (native := build.ready(start=False)) is not None:
                pieces.adopt(native)
                build = None
        layout = (blocks, n_gap_blocks, destinations, offsets, gap_rows, n)
        self.compiling = (build, pieces, layout, nlp) if build is not None else None
        nlp.residuals, nlp.g = self._block_pieces(pieces, *layout)
        nlp.lbg = [np.zeros(self.model.nx * n)]
        nlp.ubg = [np.zeros(self.model.nx * n)]

    def _model_pieces(self) -> ModelPieces:
        """The model's pieces for the gaps and sensors (`chained_jacobians`): of the model
        itself, or, where it has series of knots in time (a wind process) that the
        intervals read a few at a time (`series_slots`; `self.slots`), of the model local
        in time, whose Jacobian columns are the free parameters other than the knots, then
        each series' slots."""
        _, _, _, _, xscale, cscale = self._ctx
        m = self.model
        reach = offset_reach(m, self.values, self.free)
        self.slots: SeriesSlots | None = (None if reach is None or not self.settings.local_series
                                          else series_slots(m, self.t, self.free, reach))
        if self.slots is None:
            return ModelPieces(m, [m.parameter_names.index(f) for f in self.free],
                               self.pscale, cscale, xscale)
        local = Model(self.test, m.effects, series_slots=self.slots.slots)
        self._slot_columns = local.slot_columns
        knots = {name for names in self.slots.names.values() for name in names}
        self._unslotted = [i for i, f in enumerate(self.free) if f not in knots]
        cols = [m.parameter_names.index(self.free[i]) for i in self._unslotted]
        scales = [self.pscale[i] for i in self._unslotted]
        for series, names in self.slots.names.items():
            cols += [int(c) for c in local.slot_columns[series][1]]
            scales += [self.pscale[self.free.index(names[0])]] * self.slots.slots
        return ModelPieces(local, cols, np.asarray(scales), cscale, xscale)

    def _slot_inputs(self, block: _Block) -> ca.MX:
        """The slots' times and values of each instance of `block` (`_model_pieces`), in the
        order the model local in time appends them to its parameters (one column each)."""
        assert self.slots is not None and block.interval is not None
        pfull, first = self._ctx[2], len(self.model.parameters)
        rows: dict[int, ca.MX] = {}
        for series, names in self.slots.names.items():
            times, knots = self.slots.slot_data(series, block.interval)
            t_cols, v_cols = self._slot_columns[series]
            index = [self.model.parameter_names.index(n) for n in names]
            for j in range(self.slots.slots):
                rows[int(t_cols[j]) - first] = ca.MX(ca.DM(times[j]).T)
                rows[int(v_cols[j]) - first] = pfull[[index[k] for k in knots[j]]].T
        return ca.vertcat(*(rows[i] for i in range(len(rows))))

    def _block_pieces(self, pieces: ModelPieces, blocks: list[_Block], n_gap_blocks: int,
                      destinations: list[np.ndarray], offsets: list[int],
                      gap_rows: list[np.ndarray], n: int) -> tuple[list[_Piece], list[_Piece]]:
        """The sensors' residual pieces and the continuity gaps' constraint pieces, every
        block's values and Jacobian chained from `pieces`."""
        chains = [pieces.gap(b.chain[1]) if b.chain[0] == "gap"
                  else pieces.residual(*b.chain) for b in blocks]
        mapped = [self._mapped_block(b, value_fn, jac_fn) for b, (value_fn, jac_fn)
                  in zip(blocks, chains, strict=True)]
        residuals = _gathered(mapped[n_gap_blocks:], destinations, offsets)
        gaps = (mapped[:1] if n_gap_blocks == 1 else
                _gathered(mapped[:n_gap_blocks], gap_rows, [0, self.model.nx * n]))
        return residuals, gaps

    def _switch_to_native(self) -> PointFunctions | None:
        """Once the model's pieces compiled in the background are ready: the point functions
        (`_point_functions`) rebuilt on them, for `PointEvaluations.switch`; None before."""
        if self.compiling is None:
            return None
        build, pieces, layout, nlp = self.compiling
        native = build.ready()
        if native is None:
            if build.failed:
                self.compiling = None
            return None
        self.compiling = None
        pieces.adopt(native)
        residuals, gaps = self._block_pieces(pieces, *layout)
        nlp.residuals[:len(residuals)] = residuals
        nlp.g[:len(gaps)] = gaps
        self.functions = self._point_functions(nlp)
        return self.functions

    def _captures(self, nlp: _Nlp, h: float) -> None:
        """Captured quantities at free event times: cubic B-spline weights of node values,
        one equality each (and, for the Hessian, the same with the process knots held)."""
        m = self.model
        # For the captures' curvature, the process knots enter through a copy of P that is
        # not differentiated (`Parameter.process_knot`): a captured airspeed is smooth in
        # the air's velocity, and its exact curvature in each knot cost 0.4 s of build.
        knots = [nlp.free_index[p.name] for p in m.parameters
                 if p.process_knot and p.name in nlp.free_index]
        nlp.knots = bool(knots)
        pfull_curv = nlp.pfull
        if knots:
            held = ca.vertcat(*[nlp.P_held[i] if i in set(knots) else nlp.P[i]
                                for i in range(len(self.free))])
            pfull_curv = ca.substitute(nlp.pfull, nlp.P, held)
        for i, cap in enumerate(m.captures):
            if cap.at_time is not None:
                lo = hi = cap.at_time
                t_event = ca.MX(cap.at_time)
            else:
                prm = m.parameter(cap.time_parameter)
                fixed = prm.name not in nlp.free_index
                lo = self.values.get(prm.name, prm.default) if fixed else prm.lower
                hi = self.values.get(prm.name, prm.default) if fixed else prm.upper
                t_event = nlp.pfull[m.parameter_names.index(prm.name)]
            kw = np.flatnonzero((self.t >= lo - 2.5 * h) & (self.t <= hi + 2.5 * h))
            if np.any(np.abs(np.diff(self.t[kw]) - h) > 1e-6 * h):
                raise ValueError(f"the shooting grid is not uniform (step {h:g} s) over "
                                 f"[{lo:g}, {hi:g}] s, where {cap.name} may be captured")
            qfn = m.capture_function(cap.name).map(len(kw), "serial")
            tk = ca.DM(self.t[kw]).T
            w = cubic_bspline((t_event - tk) / h)
            con = (nlp.Cp[i] - ca.dot(w, qfn(nlp.Xp[:, kw], tk, nlp.pfull, nlp.Cp))) / nlp.cscale
            nlp.g.append(_Piece.of(con, nlp.z))
            nlp.curved.append(con if not knots else (nlp.Cp[i] - ca.dot(
                w, qfn(nlp.Xp[:, kw], tk, pfull_curv, nlp.Cp))) / nlp.cscale)
            nlp.lbg.append([0.0])
            nlp.ubg.append([0.0])

    def _effect_constraints(self, nlp: _Nlp) -> None:
        """Constraints on parameters and captured values declared by effects."""
        m = self.model
        p_sx = ca.vertcat(ca.SX(0, 1), *[m.ctx.p[p.name] for p in m.parameters])
        c_sx = ca.vertcat(ca.SX(0, 1), *[m.ctx.c[c.name] for c in m.captures])
        for con in m.constraints:
            fn = ca.Function("con", [p_sx, c_sx], [con.expr])
            nlp.g.append(_Piece.of(fn(nlp.pfull, nlp.Cp), nlp.z))
            nlp.lbg.append([con.lower])
            nlp.ubg.append([con.upper])
        # The constraints whose curvature the Hessian carries end here.
        nlp.n_small = len(nlp.g)

    def _limits(self, nlp: _Nlp, n: int) -> None:
        """What-if limits on model quantities (`Settings.limits`), at every node."""
        m, y = self.model, nlp.syms
        self.limit_rows: dict[str, tuple[slice, float]] = {}
        offset = sum(int(np.size(a)) for a in nlp.lbg)
        for qname, (lo, hi) in self.settings.limits.items():
            if qname not in m.quantity_names:
                raise ValueError(f"no model quantity {qname!r} to limit")
            finite = [abs(v) for v in (lo, hi) if np.isfinite(v) and v != 0.0]
            qscale = max(finite) if finite else 1.0
            qi = m.quantity_names.index(qname)
            fn = ca.Function("limit", [y["x"], y["t"], y["p"], y["c"]],
                             [m.quantities(y["x"], y["t"], y["p"], y["c"])[qi] / qscale])
            block = _Block(fn, [np.arange(n + 1)], self.t, [])
            nlp.g.append(self._mapped_block(block, fn, self._local_jacobian(fn, 1)))
            nlp.lbg.append(np.full(n + 1, lo / qscale))
            nlp.ubg.append(np.full(n + 1, hi / qscale))
            self.limit_rows[qname] = (slice(offset, offset + n + 1), qscale)
            offset += n + 1

    def _extra_residuals(self, nlp: _Nlp) -> None:
        """Residuals beyond the sensors': observed event times the model predicts (a
        Pilot's Main bag lift and bag strip), priors on free parameters (`ModelSpec.priors`)
        and the effects' pseudo-observations (a process prior)."""
        m = self.model
        predicted = m.event_times(nlp.pfull, nlp.Cp)
        for j, (timing, event) in enumerate(m.timings):
            r = (event.time - predicted[j]) / event.sigma
            nlp.residuals.append(_Piece.of(r, nlp.z))
            self.samples.append((EVENTS, (timing_label(timing),), np.array([event.time]),
                                  np.array([[event.time]]), np.array([[event.sigma]])))
        for name, (value, sigma) in self.spec.prior_values(m).items():
            if name not in nlp.free_index:
                raise ValueError(f"a prior on {name}, which this estimator holds fixed")
            r = (value - nlp.pfull[m.parameter_names.index(name)]) / sigma
            nlp.residuals.append(_Piece.of(r, nlp.z))
            self.samples.append((PRIORS, (name,), np.array([self.t[0]]),
                                  np.array([[value]]), np.array([[sigma]])))
        p_sx = ca.vertcat(ca.SX(0, 1), *[m.ctx.p[p.name] for p in m.parameters])
        for effect, channel, times, expr in m.penalties:
            fn = ca.Function("penalty", [p_sx], [expr])
            nlp.residuals.append(_Piece.of(fn(nlp.pfull), nlp.z))
            self.samples.append((effect, (channel,), times, np.zeros((1, times.size)),
                                  np.ones((1, times.size))))

    def _assemble(self, nlp: _Nlp, n: int) -> None:
        """The functions evaluated on the NLP: residuals and constraints with their
        Jacobians (one native evaluation per point, `nlp_functions.PointEvaluations`), the
        objective, the curvature of the few capture and effect constraints, the action
        windows, and the unpacking of a decision vector."""
        s, z_all, pieces, g = self.settings, nlp.z, nlp.residuals, nlp.g
        self.z = z_all
        residual = _stack(pieces, "symbolic")
        jac = _stack(pieces, "jacobian")
        self.g = _stack(g, "symbolic")
        constraint_jac = _stack(g, "jacobian")
        self.functions = self._point_functions(nlp)
        self.points = PointEvaluations(*self.functions, switch=self._switch_to_native)
        # The exact curvature of the few capture and effect constraints (a capture at a
        # free time bends in that time; without it a Pilot's bag-strip constraint made the
        # steps cycle); the curvature of the continuity constraints is neglected.
        small = ca.vertcat(*nlp.curved, _stack(g[1 + len(nlp.curved):nlp.n_small], "symbolic"))
        self._small = (z_all, small, (nlp.P_held, nlp.P) if nlp.knots else None)
        self._curvature_fn: tuple[ca.Function, ca.Function] | None = None
        nx = self.model.nx
        small_rows = slice(nx * n, nx * n + small.numel())
        self.lbg = np.concatenate([np.ravel(a) for a in nlp.lbg])
        self.ubg = np.concatenate([np.ravel(a) for a in nlp.ubg])
        self.damping = (MarquardtDamping(self.points, self.lbg, self.ubg)
                        if s.point_cache else None)
        self.windows = ActionWindows(
            self.points.patterns(),
            (_stack_times(pieces), _stack_times(g)), nlp.X.numel(),
            s.window_margin if s.point_cache else None)
        self.small_rows = small_rows
        if not s.point_cache:
            self.expressions = self._plain_nlp(residual, jac, constraint_jac, small_rows)
        self.unpack = ca.Function("unpack", [z_all], [nlp.Xp, nlp.pfull, nlp.Cp])
        self._residuals = ca.Function("residuals", [z_all], [p.value for p in pieces])
        self.has_inequalities = bool(np.any(self.lbg != self.ubg))  # what-if limits
        self.objective = 0.5 * ca.sumsqr(residual)
        self.sizes = (nlp.X.numel(), nlp.P.numel(), nlp.C.numel())
        self.xscale = nlp.xscale
        self.cscale = nlp.cscale

    @staticmethod
    def _point_functions(nlp: _Nlp) -> PointFunctions:
        """The residuals r(z), r with its Jacobian, the constraints g(z), g with its
        Jacobian: the functions `PointEvaluations` evaluates."""
        z, pieces, g = nlp.z, nlp.residuals, nlp.g
        return PointFunctions(
            ca.Function("residual_value", [z], [_stack(pieces, "value")]),
            ca.Function("residual_jacobian", [z], [_stack(pieces, "with_jacobian"),
                                                   _stacked_jacobian(pieces)]),
            ca.Function("constraint_value", [z], [_stack(g, "value")]),
            ca.Function("constraints", [z], [_stack(g, "with_jacobian"), _stacked_jacobian(g)]))

    def _variable_bounds(self, nlp: _Nlp) -> None:
        """Bounds of the scaled decision variables: the free parameters' own, captured
        values above their lower limits, states free but for those pinned at the start
        (and, without a GPS, the first node's horizontal motion held at zero)."""
        m, cscale, ncap = self.model, nlp.cscale, len(self.model.captures)
        X = nlp.X
        pb = [m.parameter(f) for f in self.free]
        inf = np.inf
        self.lbz = np.concatenate([np.full(X.numel(), -inf), [p.lower / sc for p, sc in
                                    zip(pb, self.pscale, strict=True)],
                                    [c.lower / cscale for c in m.captures]])
        self.ubz = np.concatenate([np.full(X.numel(), inf), [p.upper / sc for p, sc in
                                    zip(pb, self.pscale, strict=True)], np.full(ncap, inf)])
        for st in m.states:  # states known at the start of the phase: first node held
            if st.pinned:
                first_node = m.state_slice(st.name)
                self.lbz[first_node] = self.ubz[first_node] = st.initial / st.scale
        if not self.test.sensors_of("gps"):
            # Nothing observes the horizontal plane (an altimeter-only log): the phase
            # starts without horizontal motion, which then only the wind can give.
            for name in ("position", "velocity"):
                first = m.state_slice(name).start
                self.lbz[first:first + 2] = self.ubz[first:first + 2] = 0.0

    def curvature(self, upper: bool = True) -> ca.Function:
        """The curvature of the few capture and effect constraints, (z, lam_small) -> the
        Hessian of lam_small' g_small in z; its upper triangle (as Ipopt takes it) with
        `upper`.

        Built on first use: only a solve needs it, and the symbolic Hessian took
        0.6 s of each 3 s build on `drogue`, where most estimators a diagnosis builds
        (its score tests) are linearised, never solved.
        """
        if self._curvature_fn is None:
            z_all, small, knots = self._small
            lam_small = ca.MX.sym("lam_small", small.numel())
            hessian = (ca.hessian(ca.dot(lam_small, small), z_all)[0] if small.numel()
                       else ca.MX(z_all.numel(), z_all.numel()))
            if knots is not None:
                hessian = ca.substitute(hessian, *knots)
            full = ca.Function("curvature", [z_all, lam_small], [hessian])
            # Compiled, the upper triangle took as long: 7 ms on `drogue`.
            self._curvature_fn = (full, ca.Function("curvature_upper", [z_all, lam_small],
                                                    [ca.triu(full(z_all, lam_small))]))
        return self._curvature_fn[upper]

    def _plain_nlp(self, residual: ca.MX, jac: ca.MX, constraint_jac: ca.MX,
                   small_rows: slice) -> tuple[dict, dict]:
        """The NLP in the decision vector z, objective 0.5 |r(z)|^2, and Ipopt's derivatives.

        Gradient J'r and the Gauss-Newton Hessian J'J from the (compiled)
        residual Jacobian blocks, plus the small constraints' curvature.
        """
        z, empty = self.z, ca.MX.sym("p", 0, 1)
        obj = 0.5 * ca.sumsqr(residual)
        sigma_f = ca.MX.sym("sigma_f")
        lam_g = ca.MX.sym("lam_g", self.g.numel())
        hessian = sigma_f * ca.mtimes(jac.T, jac) + self.curvature(upper=False)(
            z, lam_g[small_rows])
        return {"x": z, "f": obj, "g": self.g}, {
            "jac_g": ca.Function("jac_g", [z, empty], [self.g, constraint_jac],
                                 ["x", "p"], ["g", "jac_g_x"]),
            # dense, as Ipopt's interface copies it
            "grad_f": ca.Function("grad_f", [z, empty], [obj, ca.densify(ca.mtimes(jac.T,
                                                                                   residual))],
                                  ["x", "p"], ["f", "grad_f_x"]),
            "hess_lag": ca.Function("gauss_newton", [z, empty, sigma_f, lam_g],
                                    [ca.triu(hessian)], ["x", "p", "lam_f", "lam_g"],
                                    ["hess_gamma_x_x"])}

    def _sensor_blocks(self, step: ca.Function, n: int, h: float, pieces: ModelPieces
                       ) -> tuple[list[_Block], list[np.ndarray], list[int]]:
        """The per-sample residual functions of every sensor the model observes, and where
        each block's rows go; records `self.samples`, one entry per sensor.

        A sample at a node is predicted from that node's state; a sample between
        nodes one partial RK4 step after the node before it, or, inside an interval
        integrated in sub-steps, by the cubic Hermite interpolant of its two nodes
        (`shooting_grid.hermite_state`).  Sensors sampled at the
        same times (an IMU and the load cells) share one block, so the step to each
        sample time is taken once for all of them: per such set of times, one block
        of the samples at nodes and one of those between.  The rows of every block
        are instance-major (every channel of one sample, then the next sample);
        `destinations[b]` gives, per row of block b, its row in the sensors' part of
        the residual vector, where sensor j's rows are offsets[j]..offsets[j+1]-1,
        instance-major, in the order of `self.samples`; each set of times adds a piece.
        """
        m = self.model
        xs, ts, dts = ca.SX.sym("x", m.nx), ca.SX.sym("t"), ca.SX.sym("dt")
        ps, cs = ca.SX.sym("p", len(m.parameters)), ca.SX.sym("c", len(m.captures))
        self.samples = []
        groups: list[tuple[np.ndarray, list[int]]] = []  # (sample times, sensor numbers)
        offsets = [0]
        for sensor in self.test.sensors:
            if sensor.name not in m.outputs:
                continue
            keep = (sensor.time >= self.t[0] - 1e-9) & (sensor.time <= self.t[-1] + 1e-9)
            tsamp = sensor.time[keep]
            channels = m.sensor_channels[sensor.name]
            meas = np.vstack([sensor.data[c].to_numpy()[keep] for c in channels])
            sig = np.vstack([sensor.weighting_sigma(c)[keep] for c in channels])
            number = len(self.samples)
            self.samples.append((sensor.name, channels, tsamp, meas, sig))
            offsets.append(offsets[-1] + meas.size)
            same = next((members for times, members in groups
                         if np.array_equal(times, tsamp)), None)
            if same is None:
                groups.append((tsamp, [number]))
            else:
                same.append(number)
        blocks, destinations = [], []
        long = self.steps > 1  # intervals integrated in sub-steps
        x1s, lengths = ca.SX.sym("x1", m.nx), ca.SX.sym("H")
        rhs = ca.Function("rhs", [xs, ts, ps, cs], [m.rhs(xs, ts, ps, cs)])
        for tsamp, members in groups:
            k = np.clip(np.searchsorted(self.t, tsamp + 1e-7 * h, side="right") - 1, 0, n - 1)
            dt = tsamp - self.t[k]
            between = np.abs(dt) >= 1e-7
            kinds = (~between, between & ~long[k], between & long[k])
            names = [self.samples[i][0] for i in members]
            observe = pieces.add_observation(names)
            for kind, samples in enumerate(np.flatnonzero(c) for c in kinds):
                if samples.size == 0:
                    continue
                meas = np.vstack([self.samples[i][3][:, samples] for i in members])
                sig = np.vstack([self.samples[i][4][:, samples] for i in members])
                ym, sg = ca.SX.sym("ym", meas.shape[0]), ca.SX.sym("sg", meas.shape[0])
                nodes, states = [k[samples]], [xs]
                if kind == 0:
                    x_at, t_at, sym_extra, extra = xs, ts, [], []
                elif kind == 1:
                    x_at, t_at, sym_extra, extra = (step(xs, ts, dts, ps, cs), ts + dts,
                                                    [dts], [dt[samples]])
                else:  # inside a long interval: between its nodes (`hermite_state`)
                    x_at = hermite_state(xs, x1s, rhs(xs, ts, ps, cs),
                                         rhs(x1s, ts + lengths, ps, cs), lengths, dts)
                    t_at, sym_extra = ts + dts, [dts, lengths]
                    extra = [dt[samples], np.diff(self.t)[k[samples]]]
                    nodes, states = [k[samples], k[samples] + 1], [xs, x1s]
                y_at = ca.vertcat(*[m.outputs[name](x_at, t_at, ps, cs) for name in names])
                fn = ca.Function(f"residual_{len(blocks)}",
                                 [*states, ts, *sym_extra, ym, sg, ps, cs], [(ym - y_at) / sg])
                blocks.append(_Block(fn, nodes, self.t[k[samples]], [*extra, meas, sig], (
                    observe, kind), k[samples] if self.slots is not None else None))
                # Row (sample j, channel c) of sensor i lies at offsets[i] + j n_i + c.
                destinations.append(np.concatenate([
                    offsets[i] + samples[:, None] * len(self.samples[i][1])
                    + np.arange(len(self.samples[i][1]))[None, :]
                    for i in members], axis=1).ravel())
        return blocks, destinations, offsets

    def _local_jacobian(self, fn: ca.Function, n_states: int) -> ca.Function:
        """Values and Jacobian of one instance of `fn` w.r.t. its scaled states, free
        parameters and captures.

        Same inputs as `fn`; the outputs are its m values and the column-major
        m x (nx*n_states + free parameters + captures) block, formed at SX
        level (CasADi picks forward or reverse mode for this small function).
        """
        _, _, _, _, xscale, cscale = self._ctx
        m = self.model
        args = fn.sx_in()
        xs_args, p_arg, c_arg = args[:n_states], args[-2], args[-1]
        out = fn(*args)
        free_cols = [m.parameter_names.index(f) for f in self.free]
        mrows = out.numel()
        jblocks = [ca.jacobian(out, a) * ca.repmat(ca.DM(xscale).T, mrows, 1) for a in xs_args]
        jp = ca.jacobian(out, p_arg)[:, free_cols] * ca.repmat(ca.DM(self.pscale).T, mrows, 1)
        jc = ca.jacobian(out, c_arg) * cscale
        return ca.Function(f"{fn.name()}_jac", args,
                           [out, ca.vec(ca.horzcat(*jblocks, jp, jc))])

    def _instance_arguments(self, block: _Block) -> list:
        """The arguments of `block.fn` for all its instances at once (one column each); where
        its chain reads the knots of the model local in time, the slots' times and values
        last (`_slot_inputs`), which `block.fn` does not take."""
        _, Xp, pfull, Cp, _, _ = self._ctx
        slots = [] if block.interval is None else [self._slot_inputs(block)]
        return [*(Xp[:, k] for k in block.nodes), ca.DM(block.times).T,
                *(ca.DM(d) if np.ndim(d) == 2 else ca.DM(d).T for d in block.data), pfull, Cp,
                *slots]

    def _instance_columns(self, block: _Block) -> np.ndarray:
        """Per instance of `block`, the decision-vector index of each local column (its
        states, then the free parameters and captures; as in `_local_jacobian`)."""
        nx, nX = self.model.nx, self._ctx[0].numel()
        nfree, ncap = len(self.free), len(self.model.captures)
        n_states = len(block.nodes)
        zcols = np.empty((len(block.times), nx * n_states + nfree + ncap), dtype=np.int64)
        for j, k in enumerate(block.nodes):
            zcols[:, j * nx:(j + 1) * nx] = (np.asarray(k)[:, None] * nx + np.arange(nx))
        zcols[:, nx * n_states:] = nX + np.arange(nfree + ncap)
        if block.interval is None or self.slots is None:
            return zcols
        # The model local in time: the free parameters but the knots, then each series'
        # slots, which are the knots the instance reads (`_model_pieces`).
        free_index = {f: i for i, f in enumerate(self.free)}
        cols = [nX + np.array(self._unslotted)[None, :].repeat(len(block.times), axis=0)]
        for series, names in self.slots.names.items():
            _, knots = self.slots.slot_data(series, block.interval)
            index = np.array([free_index[name] for name in names])
            cols.append(nX + index[knots].T)
        cols.append(nX + nfree + np.arange(ncap)[None, :].repeat(len(block.times), axis=0))
        return np.concatenate([zcols[:, :nx * n_states], *cols], axis=1)

    def _mapped_block(self, block: _Block, value_fn: ca.Function,
                      local: ca.Function) -> _Piece:
        """Values and Jacobian (w.r.t. the scaled decision vector) of `block` over its instances.

        `block.fn(x_a, x_b, ..., t, *data, p, c)` takes one state per entry of
        `block.nodes` (node indices per instance), a time, per-instance data
        columns, and the full parameter and capture vectors; it returns a
        vector of m values.  `value_fn` computes the same (native code, or
        `block.fn` itself), `local` its values and single-instance Jacobian
        (`_local_jacobian`); all are mapped over the instances, and the
        Jacobian values are scattered into the global sparse Jacobian.
        Differentiating the mapped graph directly would take one sweep per
        colour of the whole Jacobian, about as many as there are parameters.
        """
        n_inst = len(block.times)
        mrows = block.fn.numel_out(0)
        call = self._instance_arguments(block)

        def mapped(fn: ca.Function) -> list[ca.MX]:
            out = fn.map(n_inst, "thread", 2)(*call[:fn.n_in()])
            return [ca.vec(o) for o in (out if isinstance(out, tuple | list) else [out])]

        with_jacobian, nz = mapped(local)
        zcols = self._instance_columns(block)
        ncols = zcols.shape[1]
        rows = (np.arange(n_inst)[:, None] * mrows + np.arange(mrows)[None, :])
        r_full = np.repeat(rows[:, None, :], ncols, axis=1).reshape(-1)
        c_full = np.repeat(zcols[:, :, None], mrows, axis=2).reshape(-1)
        # Column-major order.  Each instance holds a column once, with its rows in order,
        # and the instances' rows increase: a stable sort by column orders the rows too.
        order = np.argsort(c_full, kind="stable")
        n_z = self._ctx[0].numel() + len(self.free) + len(self.model.captures)
        colind = np.searchsorted(c_full[order], np.arange(n_z + 1))
        sp = ca.Sparsity(n_inst * mrows, n_z, colind.tolist(), r_full[order].tolist())
        return _Piece(mapped(block.fn)[0], mapped(value_fn)[0], with_jacobian,
                      ca.MX(sp, nz[order.tolist()]), np.repeat(block.times, mrows))

    def size_text(self) -> str:
        """One line describing the NLP's size."""
        nX, nP, nC = self.sizes
        return (f"{nX + nP + nC} variables ({nX} shooting states on {len(self.t)} nodes, "
                f"{nP} parameters, {nC} captured speeds), {self.g.numel()} constraints, "
                f"{sum(len(s_[2]) * len(s_[1]) for s_ in self.samples)} residuals")

    def violations(self, g: np.ndarray) -> np.ndarray:
        """How far each constraint value in `g` lies outside its bounds (scaled)."""
        return bound_violations(g, self.lbg, self.ubg)

    def value_violation(self, z: np.ndarray) -> float:
        """Largest scaled constraint violation at `z`, from the constraint values alone (the
        same figure as `Linearisation.violation` there; NaN where not finite)."""
        g = self.points.constraint_value(z)
        if not np.all(np.isfinite(g)):
            return np.nan
        return float(np.max(self.violations(g), initial=0.0))

    def with_value(self, z: np.ndarray, name: str, value: float) -> np.ndarray:
        """A copy of the decision vector `z` with the free parameter `name` at `value` (SI)."""
        i = self.free.index(name)
        out = z.copy()
        out[self.param_index[i]] = value / self.pscale[i]
        return out

    def free_values(self, z: np.ndarray) -> dict[str, float]:
        """The free parameters at the decision vector `z` (SI)."""
        values = z[self.param_index] * self.pscale
        return dict(zip(self.free, map(float, values), strict=True))

    @property
    def param_index(self) -> np.ndarray:
        """Where the free parameters sit in the decision vector."""
        nX, nP, _ = self.sizes
        return np.arange(nX, nX + nP)

    def fit_at(self, z: np.ndarray, stats: SolverStats) -> Fit:
        """The Fit at the decision vector `z`: trajectory, parameters, captured values and
        every sensor's residuals, with the solve's `stats`."""
        m = self.model
        Xp, pfull, Cp = (np.asarray(a) for a in self.unpack(z))
        params = {p.name: float(v) for p, v in zip(m.parameters, pfull.ravel(), strict=True)}
        caps = {c.name: float(v) for c, v in zip(m.captures, Cp.ravel(), strict=True)}
        blocks = self._residuals(z)
        blocks = blocks if isinstance(blocks, tuple | list) else [blocks]
        residuals = []
        for (sensor, channels, tsamp, meas, sig), r in zip(self.samples, blocks, strict=True):
            # Residual blocks are instance-major: (meas - model) / sigma per sample.
            r = np.asarray(r).reshape(len(tsamp), len(channels)).T
            y = meas - r * sig
            for j, ch in enumerate(channels):
                residuals.append(SensorResidual(sensor, ch, tsamp, meas[j], y[j], sig[j]))
        return Fit(self.test, m, params, list(self.free), dict(self.guess), self.t, Xp.T, caps,
                   residuals, stats, self.settings, z)
