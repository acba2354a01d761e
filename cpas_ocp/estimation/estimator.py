"""One test phase as one multiple-shooting NLP, solved by Ipopt.

Decision variables (all scaled to order one):

* the state at every node t_k of the shooting grid (multiple shooting; the
  grid is fine where the motion changes fast and coarse in steady descent,
  `shooting_grid`; the initial state is free and GPS pins it; in a test without
  GPS, only the altimeter, the first node's horizontal position and velocity
  are held at zero and the motion stays vertical unless there is wind);
* the free model parameters (inflation parameters, scale factors, inflation
  start times ...), between their bounds;
* the captured quantities (each stage's start airspeed V_i), tied to the
  trajectory by V_i = sum_k B((t_i - t_k)/h) |v_air(x_k)|, the cubic
  B-spline smoothing of node airspeeds at the free start time t_i (C2 in t_i,
  error h^2/6 |V''|, below 1e-4 m/s here; the grid is uniform, of the finest
  step h, over the window t_i may take).

Constraints: continuity x_{k+1} = RK4^M(x_k, t_k, p, c) on every interval,
the capture relations, and the effects' parameter constraints.

Objective: half the chi-square of all sensor samples in the phase,
0.5 sum ((y - h(x(t_s), t_s, p, c)) / sigma)^2, where x(t_s) is the node state
or, for a sample between nodes, one RK4 step from the node before it.
Weights use the manifest's sigmas; relative noise is evaluated at the mean
of each sample's neighbours in the measured series (`Sensor.weighting_sigma`),
so the weights neither depend on the parameters nor on the sample's own noise.
"""

from __future__ import annotations

import itertools
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from cpas_ocp import interrupts
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.action_windows import ActionWindows
from cpas_ocp.estimation.compiled import compile_functions
from cpas_ocp.estimation.feasible_descent import DescentEnd, DescentProblem, descend
from cpas_ocp.estimation.kinematic_track import kinematic_track
from cpas_ocp.estimation.nlp_functions import MarquardtDamping, PointEvaluations, ipopt_functions
from cpas_ocp.estimation.reduction import initial_guess
from cpas_ocp.estimation.shooting_grid import TimeWindow, dynamics_grid, stable_refinement
from cpas_ocp.estimation.simulate import rk4_step, simulate
from cpas_ocp.estimation.uncertainty import (
    DECREMENT_FLOOR,
    HESSIANS,
    Covariance,
    GaussNewtonStep,
    Linearization,
    gauss_newton,
    gauss_newton_step,
    kkt_covariance,
    linearize,
    log_det_information,
    measured_decrement,
)
from cpas_ocp.io.flight_test import FlightTest
from cpas_ocp.io.model_spec import ModelSpec, spec_from_effects, spec_of_test
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.model import CORE_STATES, Model, timing_label


@dataclass
class Settings:
    """Transcription and solver settings.

    grid_step (s): a uniform shooting interval, forced (None: a grid chosen
    from the dynamics, `shooting_grid`, on the lattice of the finest sampling
    interval of the test's sensors, `default_grid_step`);
    nodes: the grid's nodes (s) as given; an estimator records its grid here,
    so that a model built from its settings (a nested or extended fit, a
    profile) shares it;
    substeps: RK4 steps per interval;
    chi2_step_tol: stop once the Gauss-Newton step would lower chi-square by
    less than this (0.01: every parameter within 0.1 sigma of the optimum the
    fit is heading for; None: only Ipopt's own tests end the run);
    compile: evaluate the per-interval and per-sample Jacobians as native
    code (`cpas_ocp.estimation.compiled`; falls back to CasADi's VM without a compiler);
    free: parameter names to estimate (default: the model's choice,
    `ModelSpec.free_names`);
    fixed: values of parameters held fixed (default: their model default);
    limits: model quantities held within (lower, upper) (SI) at every node,
    e.g. ``{"tension[drogue1]": (-inf, 133e3)}``: a what-if on a derived
    quantity (`whatif`).  Between nodes the quantity is not checked.
    watchdog_trigger: Ipopt's watchdog_shortened_iter_trigger, the number of
    successive shortened line-search steps after which a full step is tried
    on trust (Ipopt's default is 10).  The Gauss-Newton Hessian leaves out the
    shooting gaps' curvature, so far from the optimum its steps are cut again
    and again while a full step would do: on `drogue_full` from the reduction
    a trigger of 3 ends in 31 iterations, 10 in 41, at the same chi-square.
    polish: let the statistical test finish a nearly feasible run with one
    Gauss-Newton step of its own (`Estimator._stop_test`; False: the earlier
    path, for benchmarks).
    point_cache: give Ipopt functions that share one native evaluation of the
    residuals, constraints and their Jacobians per point (`nlp_functions`;
    False: CasADi expressions, each evaluating what it needs in turn, the
    earlier path, for benchmarks).
    damping: Levenberg-Marquardt damping of the Gauss-Newton Hessian where its
    steps fail to deliver (`nlp_functions.MarquardtDamping`; needs point_cache).
    levenberg: a Levenberg term on the free parameters' diagonal of the Hessian
    Ipopt is given (per scaled unit squared; `nlp_functions.ipopt_functions`,
    needs point_cache; None: the earlier path).  It bounds the steps along
    parameters the data hardly determine at the iterate, such as a stiff
    elastic riser's damping ratio, whose Gauss-Newton steps were cut to
    1/128-1/256 and sent the watchdog's trial steps to chi-square 1e5-1e8.
    window_margin (s): Ipopt gets each parameter's Jacobian entries only within
    its window of action at the start, widened by this much on each side
    (`action_windows`; a solve restarts with wider windows when a parameter
    acts outside them); None gives Ipopt every structural entry (the earlier
    path; needs point_cache).
    descent_steps: a run whose chi-square has stopped falling (STALL_ITERATIONS)
    is stopped, and at most this many Gauss-Newton steps through feasible
    points from its iterate may finish the fit at the statistical test
    (`feasible_descent`); they count as iterations.  Where they do not, Ipopt
    goes on from its iterate.  A finish, not a second engine: on the
    misspecified refits it served, 8-11 steps ended the run, and a descent
    that needed 29 had ended in a worse minimum than Ipopt's.  0: Ipopt runs
    on to its limit (the earlier path, for benchmarks).
    descent_curvature: the descent learns what the Gauss-Newton model leaves out,
    the curvature of chi-square along the feasible curve (each failed trial's
    parabola sets the next trial, and two trials on one parabola whose least
    value lies within the tolerance end it: `feasible_descent`) and the
    residuals' own curvature, from the steps taken (`structured_secant`; it
    shapes the steps, while the test that ends the descent stays Gauss-Newton's).
    False: Gauss-Newton steps halved where they fail, and at most 15 of them
    (the earlier path, for benchmarks; `benchmarks/descent_finish.py`).
    """

    grid_step: float | None = None
    nodes: tuple[float, ...] | None = None
    substeps: int = 1
    max_iter: int = 500
    tol: float = 1e-6
    chi2_step_tol: float | None = 0.01
    compile: bool = True
    free: list[str] | None = None
    fixed: dict[str, float] = field(default_factory=dict)
    guess: dict[str, float] = field(default_factory=dict)
    verbose: bool = False
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    watchdog_trigger: int = 3
    polish: bool = True
    point_cache: bool = True
    damping: bool = True
    levenberg: float | None = 1.0
    window_margin: float | None = 0.5
    descent_steps: int = 30
    descent_curvature: bool = True


MIN_GRID_STEP_S = 0.001
MAX_LATTICE_STEP_S = 0.025  # the lattice resolves a fill within a 10 Hz sample (s)


def default_grid_step(test: FlightTest) -> float:
    """The finest shooting interval: one per sample of the fastest sensor, at most
    MAX_LATTICE_STEP_S, rounded down to whole ms (s); the grid from the dynamics
    (`shooting_grid`) lies on its lattice.

    A sensor sampled every dt sees the dynamics on that scale; the one RK4
    step per interval is then accurate to well below the noise for the Eq. 5/6
    inflation curves, whose fill times span many sampling intervals.  On the
    `fbcp` problem (fill in about 0.13 s, 200 Hz data) a 10 ms grid biases the
    fit to chi^2/dof = 1.2, while 5 ms and 2 ms agree with each other.

    A rocket's logger samples at 10 Hz, and its main can fill within one
    sample (the TeleMetrum Prometheus log reads free fall, then 13 g a sample
    later).  An RK4 step across a fill no longer than itself is inaccurate, and
    its error is not smooth in the start time and fill constant: on that log
    with the wind process and the accelerometer, Ipopt wandered for 500
    iterations at a 0.1 s lattice, converged in 282 at 0.05 s and in 135 at
    0.025 s; on the TeleMega log the 0.1 s lattice put the fill constant on its
    0.3 bound, where 0.025 s gives n = 4.4 in 22 iterations
    (`benchmarks/fill_resolution.py`).  The grid stays coarse in steady descent
    (1,295 nodes to 1,387).  On `rocket_gusts` with the wind process 45 of 50
    seeds converged against 49 at 0.1 s, the five others wandering along the
    drogue's opening near apogee, which the data barely determine; since the
    stalled runs' descent learns the curvature (`Settings.descent_curvature`)
    all 50 converge.
    """
    dt = min(float(np.median(np.diff(s.time))) for s in test.sensors if len(s.time) > 1)
    dt = min(dt, MAX_LATTICE_STEP_S)
    return max(MIN_GRID_STEP_S, np.floor(dt / MIN_GRID_STEP_S + 1e-6) * MIN_GRID_STEP_S)


@dataclass
class SensorResidual:
    """One sensor channel: sample times, measurement, model, sigma (SI)."""

    sensor: str
    channel: str
    t: np.ndarray
    measured: np.ndarray
    model: np.ndarray
    sigma: np.ndarray

    @property
    def normalized(self) -> np.ndarray:
        return (self.measured - self.model) / self.sigma


# Sensor name under which observed event times appear among the residuals.
EVENTS = "events"
# Sensor name under which the model's priors on free parameters appear (`ModelSpec.priors`).
PRIORS = "priors"
# Residuals that are not a sensor's time series.
PSEUDO_SENSORS = (EVENTS, PRIORS)

# Status of a run ended by the statistical test (`Settings.chi2_step_tol`).
STATISTICALLY_CONVERGED = "Solved_Gauss_Newton_Step_Below_Tolerance"
# Status of a run stopped because chi-square no longer fell (`STALL_ITERATIONS`), and of
# one such that Gauss-Newton steps through feasible points finished at the statistical
# test (`feasible_descent`).
STALLED = "Stalled_Without_Progress"
DESCENT_CONVERGED = "Solved_Feasible_Descent_After_Stall"
# Largest scaled constraint violation at which that test may stop a run.
STOP_CONSTRAINT_TOL = 1e-6
# Largest scaled violation from which the test tries one Gauss-Newton step of its own to
# finish the run (`Estimator._stop_test`): Ipopt's Gauss-Newton iterations close the last
# shooting gaps only as fast as the steps shrink, linearly.
POLISH_CONSTRAINT_TOL = 1e-3
# Gauss-Newton steps the statistical test may take of its own from an iterate before
# it has a point to end the run at (`Estimator._finishing_steps`); one more polishes it.
FINISHING_STEPS = 3
# Alternations of integrating the trajectory and meeting the other constraints that
# `Estimator.feasible_point` makes (each correction moves the trajectory only slightly).
FEASIBILITY_SWEEPS = 5


@dataclass
class SolverStats:
    status: str
    success: bool
    iterations: int
    wall_s: float
    objective: float
    worst_constraint: str = ""
    chi2_decrement: float | None = None
    start: str = "the offline reduction"  # where the solve started from


@dataclass
class Fit:
    """A converged reconstruction of one test phase."""

    test: FlightTest
    model: Model
    parameters: dict[str, float]
    free: list[str]
    guess: dict[str, float]
    t: np.ndarray
    x: np.ndarray
    captures: dict[str, float]
    residuals: list[SensorResidual]
    solver: SolverStats
    settings: Settings
    z: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    # Lagrange multipliers of the NLP's constraints at the solution (CasADi's sign).
    multipliers: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    # d(chi^2)/d(value) of each parameter a what-if bound holds (SI; see `Estimator.solve`).
    sensitivities: dict[str, float] = field(default_factory=dict)

    @property
    def chi_square(self) -> float:
        return float(sum(np.sum(r.normalized**2) for r in self.residuals))

    @property
    def n_samples(self) -> int:
        return int(sum(r.t.size for r in self.residuals))

    @property
    def dof(self) -> int:
        """Degrees of freedom of the fit: residuals minus free parameters (at least 1)."""
        return max(self.n_samples - len(self.free), 1)

    @property
    def pseudo_sensors(self) -> tuple[str, ...]:
        """Residual groups that are not a sensor's samples: observed event times, priors, and
        the effects' pseudo-observations (a wind process's innovations)."""
        return (*PSEUDO_SENSORS, *dict.fromkeys(e for e, *_ in self.model.penalties))

    def quantities(self) -> dict[str, np.ndarray]:
        """Every scalar model quantity (cds[P], tension[P], dynamic_pressure, ...) on the grid."""
        return self.model.quantities_along(self.t, self.x, self.parameters, self.captures)


class Estimator:
    """Builds the NLP of one test phase once; `solve` may then be called repeatedly."""

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
            self.t = np.asarray(s.nodes, dtype=float)
            if len(m.states) > len(CORE_STATES):  # an effect's states: maybe a fast mode
                self.t = self._stable_grid(self.t)
        elif s.grid_step is not None:
            n = int(np.floor((test.t_end - test.t_start) / s.grid_step + 1e-9))
            self.t = test.t_start + s.grid_step * np.arange(n + 1)
        else:
            self.t = self._dynamics_grid(default_grid_step(test))
        self.settings = replace(s, nodes=tuple(self.t))
        # The finest interval, rounded to the microsecond: the B-spline's spacing.
        self.fine_step = float(np.round(np.min(np.diff(self.t)), 6))
        self._build(len(self.t) - 1, self.fine_step)

    def _stable_grid(self, nodes: np.ndarray) -> np.ndarray:
        """Given nodes, refined where this model's own states need finer steps for RK4 to
        stay stable (`shooting_grid.stable_refinement`)."""
        fine_step = float(np.round(np.min(np.diff(nodes)), 6))
        return stable_refinement(nodes, self.model, self.values, self._first_state(fine_step),
                                 fine_step)

    def _dynamics_grid(self, fine_step: float) -> np.ndarray:
        """The nodes chosen from the model's dynamics at the first guesses (`shooting_grid`)."""
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
        """The guessed state at the phase's start (`_guessed_states`; the effects' guesses
        take a rate from the first two lattice points)."""
        t0 = self.test.t_start
        return self._guessed_states(np.array([t0, t0 + fine_step]))[0][:, 0]

    # ------------------------------------------------------------------ transcription
    def _build(self, n: int, h: float) -> None:
        """The NLP on the grid `self.t` of n intervals, the finest h long (s)."""
        m, s = self.model, self.settings
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

        step = self._step = rk4_step(m)
        xs = ca.SX.sym("x", nx)
        xs1 = ca.SX.sym("x1", nx)
        ts = ca.SX.sym("t")
        dts = ca.SX.sym("dt")
        ps = ca.SX.sym("p", len(m.parameters))
        cs = ca.SX.sym("c", ncap)
        xe = xs
        for j in range(s.substeps):
            xe = step(xe, ts + j * dts / s.substeps, dts / s.substeps, ps, cs)
        self._ctx = (X, Xp, pfull, Cp, xscale, cscale)

        # Per-instance functions, each mapped over its instances with its Jacobian:
        # the continuity gap of every shooting interval, and the weighted residuals of
        # every sample of every sensor (sensors sampled between nodes are predicted one
        # partial RK4 step after the node before the sample).
        ks = np.arange(n)
        blocks = [_Block(ca.Function("gap", [xs, xs1, ts, dts, ps, cs], [(xs1 - xe) / xscale]),
                         [ks, ks + 1], self.t[:n], [np.diff(self.t)])]
        sensor_blocks, destinations, offsets = self._sensor_blocks(step, n, h)
        blocks += sensor_blocks
        # Each block's values (the line search's trial points) and its values with the
        # Jacobian (accepted points) run as native code; the functions themselves stay
        # in CasADi's VM as well, for the differentiable graph (`_obj`, `_g`).
        local = [self._local_jacobian(b.fn, len(b.nodes)) for b in blocks]
        native = [b.fn for b in blocks] + local
        if s.compile:
            native = compile_functions(native)
        mapped = [self._mapped_block(b, value_fn, jac_fn) for b, value_fn, jac_fn
                  in zip(blocks, native[:len(blocks)], native[len(blocks):], strict=True)]
        residual_pieces = _gathered(mapped[1:], destinations, offsets)
        g = [mapped[0]]
        lbg = [np.zeros(nx * n)]
        ubg = [np.zeros(nx * n)]

        # Captured quantities at free event times: cubic B-spline weights of node values.
        z_all = ca.vertcat(ca.vec(X), P, C)
        # For the captures' curvature, the process knots enter through a copy of P that is
        # not differentiated (`Parameter.process_knot`): a captured airspeed is smooth in
        # the air's velocity, and its exact curvature in each knot cost 0.4 s of build.
        knots = [free_index[p.name] for p in m.parameters
                 if p.process_knot and p.name in free_index]
        P_held = ca.MX.sym("P_held", len(self.free))
        pfull_curv = pfull
        if knots:
            held = ca.vertcat(*[P_held[i] if i in set(knots) else P[i]
                                for i in range(len(self.free))])
            pfull_curv = ca.substitute(pfull, P, held)
        curved: list[ca.MX] = []
        for i, cap in enumerate(m.captures):
            if cap.at_time is not None:
                lo = hi = cap.at_time
                t_event = ca.MX(cap.at_time)
            else:
                prm = m.parameter(cap.time_parameter)
                fixed = prm.name not in free_index
                lo = self.values.get(prm.name, prm.default) if fixed else prm.lower
                hi = self.values.get(prm.name, prm.default) if fixed else prm.upper
                t_event = pfull[m.parameter_names.index(prm.name)]
            kw = np.flatnonzero((self.t >= lo - 2.5 * h) & (self.t <= hi + 2.5 * h))
            if np.any(np.abs(np.diff(self.t[kw]) - h) > 1e-6 * h):
                raise ValueError(f"the shooting grid is not uniform (step {h:g} s) over "
                                 f"[{lo:g}, {hi:g}] s, where {cap.name} may be captured")
            qfn = m.capture_function(cap.name).map(len(kw), "serial")
            node_vals = qfn(Xp[:, kw], ca.DM(self.t[kw]).T, pfull, Cp)
            w = cubic_bspline((t_event - ca.DM(self.t[kw]).T) / h)
            con = (Cp[i] - ca.dot(w, node_vals)) / cscale
            g.append(_Piece.of(con, z_all))
            curved.append(con if not knots else
                          (Cp[i] - ca.dot(w, qfn(Xp[:, kw], ca.DM(self.t[kw]).T, pfull_curv,
                                                 Cp))) / cscale)
            lbg.append([0.0])
            ubg.append([0.0])

        # Constraints on parameters and captured values declared by effects.
        p_sx = ca.vertcat(ca.SX(0, 1), *[m.ctx.p[p.name] for p in m.parameters])
        c_sx = ca.vertcat(ca.SX(0, 1), *[m.ctx.c[c.name] for c in m.captures])
        for con in m.constraints:
            fn = ca.Function("con", [p_sx, c_sx], [con.expr])
            g.append(_Piece.of(fn(pfull, Cp), z_all))
            lbg.append([con.lower])
            ubg.append([con.upper])

        # What-if limits on model quantities, at every node (after the few constraints
        # whose curvature the Hessian carries).
        n_small = len(g)
        self.limit_rows: dict[str, tuple[slice, float]] = {}
        offset = sum(int(np.size(a)) for a in lbg)
        for qname, (lo, hi) in s.limits.items():
            if qname not in m.quantity_names:
                raise ValueError(f"no model quantity {qname!r} to limit")
            finite = [abs(v) for v in (lo, hi) if np.isfinite(v) and v != 0.0]
            qscale = max(finite) if finite else 1.0
            qi = m.quantity_names.index(qname)
            fn = ca.Function("limit", [xs, ts, ps, cs], [m.quantities(xs, ts, ps, cs)[qi] / qscale])
            block = _Block(fn, [np.arange(n + 1)], self.t, [])
            g.append(self._mapped_block(block, fn, self._local_jacobian(fn, 1)))
            lbg.append(np.full(n + 1, lo / qscale))
            ubg.append(np.full(n + 1, hi / qscale))
            self.limit_rows[qname] = (slice(offset, offset + n + 1), qscale)
            offset += n + 1

        # Observed event times the model predicts (a Pilot's Main bag lift and bag strip).
        predicted = m.event_times(pfull, Cp)
        for j, (timing, event) in enumerate(m.timings):
            r = (event.time - predicted[j]) / event.sigma
            residual_pieces.append(_Piece.of(r, z_all))
            self._samples.append((EVENTS, (timing_label(timing),), np.array([event.time]),
                                  np.array([[event.time]]), np.array([[event.sigma]])))

        # Priors on free parameters: independent measurements of them (`ModelSpec.priors`).
        for name, (value, sigma) in self.spec.prior_values(m).items():
            if name not in free_index:
                raise ValueError(f"a prior on {name}, which this estimator holds fixed")
            r = (value - pfull[m.parameter_names.index(name)]) / sigma
            residual_pieces.append(_Piece.of(r, z_all))
            self._samples.append((PRIORS, (name,), np.array([self.t[0]]),
                                  np.array([[value]]), np.array([[sigma]])))

        # Effects' pseudo-observations (a process prior): residuals of the parameters alone.
        for effect, channel, times, expr in m.penalties:
            fn = ca.Function("penalty", [p_sx], [expr])
            residual_pieces.append(_Piece.of(fn(pfull), z_all))
            self._samples.append((effect, (channel,), times, np.zeros((1, times.size)),
                                  np.ones((1, times.size))))

        self._z = z_all
        residual = _stack(residual_pieces, "symbolic")
        jac = _stack(residual_pieces, "jacobian")
        self._g = _stack(g, "symbolic")
        constraint_jac = _stack(g, "jacobian")
        self._residual_value = ca.Function("residual_value", [z_all],
                                           [_stack(residual_pieces, "value")])
        self._residual_jacobian = ca.Function("residual_jacobian", [z_all],
                                              [_stack(residual_pieces, "with_jacobian"), jac])
        self._constraint_value = ca.Function("constraint_value", [z_all], [_stack(g, "value")])
        self._constraints = ca.Function("constraints", [z_all],
                                        [_stack(g, "with_jacobian"), constraint_jac])
        self._points = PointEvaluations(self._residual_value, self._residual_jacobian,
                                        self._constraint_value, self._constraints)
        obj = 0.5 * ca.sumsqr(residual)
        # The exact curvature of the few capture and effect constraints (a capture at a
        # free time bends in that time; without it a Pilot's bag-strip constraint made the
        # steps cycle); the curvature of the continuity constraints is neglected.
        small = ca.vertcat(*curved, _stack(g[1 + len(curved):n_small], "symbolic"))
        lam_small = ca.MX.sym("lam_small", small.numel())
        hessian = (ca.hessian(ca.dot(lam_small, small), z_all)[0] if small.numel()
                   else ca.MX(z_all.numel(), z_all.numel()))
        if knots:
            hessian = ca.substitute(hessian, P_held, P)
        curvature = ca.Function("curvature", [z_all, lam_small], [hessian])
        small_rows = slice(nx * n, nx * n + small.numel())
        lbg_all = np.concatenate([np.ravel(a) for a in lbg])
        ubg_all = np.concatenate([np.ravel(a) for a in ubg])
        self._damping = (MarquardtDamping(self._points, lbg_all, ubg_all)
                         if s.point_cache and s.damping else None)
        self._windows = ActionWindows(
            (self._points._buffers["rJ"].pattern(1), self._points._buffers["gA"].pattern(1)),
            (_stack_times(residual_pieces), _stack_times(g)), X.numel(),
            s.window_margin if s.point_cache else None)
        # Its upper triangle, as Ipopt takes it (compiled, it took as long: 7 ms on `drogue`).
        self._curvature = ca.Function("curvature_upper", [z_all, lam_small],
                                      [ca.triu(curvature(z_all, lam_small))])
        self._small_rows = small_rows
        if not s.point_cache:
            self._expressions = self._plain_nlp(residual, jac, constraint_jac, curvature,
                                                small_rows)
        self._unpack = ca.Function("unpack", [z_all], [Xp, pfull, Cp])
        self._residuals = ca.Function("residuals", [z_all], [p.value for p in residual_pieces])
        self._lbg, self._ubg = lbg_all, ubg_all
        self._has_inequalities = bool(np.any(self._lbg != self._ubg))  # what-if limits
        self._obj = obj
        self._nz = (X.numel(), P.numel(), C.numel())
        self._xscale = xscale
        self._cscale = cscale
        pb = [m.parameter(f) for f in self.free]
        inf = np.inf
        self._lbz = np.concatenate([np.full(X.numel(), -inf), [p.lower / sc for p, sc in
                                    zip(pb, self.pscale, strict=True)],
                                    [c.lower / cscale for c in m.captures]])
        self._ubz = np.concatenate([np.full(X.numel(), inf), [p.upper / sc for p, sc in
                                    zip(pb, self.pscale, strict=True)], np.full(ncap, inf)])
        for st in m.states:  # states known at the start of the phase: first node held
            if st.pinned:
                first_node = m.state_slice(st.name)
                self._lbz[first_node] = self._ubz[first_node] = st.initial / st.scale
        if not self.test.sensors_of("gps"):
            # Nothing observes the horizontal plane (an altimeter-only log): the phase
            # starts without horizontal motion, which then only the wind can give.
            for name in ("position", "velocity"):
                first = m.state_slice(name).start
                self._lbz[first:first + 2] = self._ubz[first:first + 2] = 0.0
        # Gauss-Newton converges linearly, so Ipopt's dual infeasibility plateaus near
        # 1e-4 (scaled) long after the estimate has stopped moving; accept a point where
        # the objective no longer changes (relative 1e-9, i.e. ~1e-5 in chi-square, over
        # 5 iterations; a change of 1 in chi-square is the statistical scale) and the
        # constraints hold to 1e-8.  `solve` reports which criterion ended the run.
        self._options = {
            "ipopt.max_iter": s.max_iter, "ipopt.tol": s.tol,
            "ipopt.acceptable_tol": 1e-1, "ipopt.acceptable_iter": 5,
            "ipopt.acceptable_obj_change_tol": 1e-9,
            "ipopt.acceptable_constr_viol_tol": 1e-8,
            "ipopt.watchdog_shortened_iter_trigger": s.watchdog_trigger,
            "ipopt.print_level": 5 if s.verbose else 0, "print_time": False,
            "ipopt.sb": "yes",
            # The NLP is scaled by construction (states and parameters by their scales,
            # residuals by their sigmas): MUMPS's own row and column scaling (MC64's
            # permuting scaling and MC77's, computed afresh for every factorisation)
            # changes no step here and cost 40 % of the KKT solves on `drogue_full`,
            # and its analysis phase went from 0.6-1.8 s to 0.1 s without it.
            "ipopt.mumps_permuting_scaling": 0, "ipopt.mumps_scaling": 0,
        }
        self._hessian_product: ca.Function | None = None
        # the solver keeps only a reference to its callbacks
        self._monitor = _Monitor(self._z.numel(), self._g.numel(), self._violations,
                                 self._stop_test, s.chi2_step_tol, self._damping,
                                 STALL_ITERATIONS if s.descent_steps > 0 else None)
        self._make_solver()

    def _make_solver(self, barrier: float | None = None) -> None:
        """Ipopt on the NLP, its derivatives on the pattern `self._windows` keeps; with
        `barrier`, warm-started (the caller passes the multipliers) at that barrier
        parameter, the bounds not pushed."""
        if self.settings.point_cache:
            self._ipopt = ipopt_functions(self._points, self._curvature, self._small_rows,
                                          self._windows, self._monitor.window_check,
                                          self._damping, self._levenberg())
            nlp, derivatives = self._ipopt.nlp, self._ipopt.options
        else:
            nlp, derivatives = self._expressions
        self._warm = barrier is not None
        warm = {} if barrier is None else {
            "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": barrier,
            "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9}
        self._solver = ca.nlpsol("reconstruction", "ipopt", nlp, {
            **self._options, **warm, **derivatives, "iteration_callback": self._monitor})

    def _levenberg(self) -> tuple[np.ndarray, float] | None:
        """The Levenberg term's columns of z (the free parameters) and size, or None."""
        delta = self.settings.levenberg
        return None if not delta else (self._param_index, float(delta))

    def _jacobian_values(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The stored values of the residual and constraint Jacobians at `z`."""
        return self._points.residual_jacobian(z)[1].data, self._points.constraints(z)[1].data

    def _fit_windows(self, *points: np.ndarray, widen: bool = False,
                     barrier: float | None = None) -> None:
        """Fit the parameters' windows of action to their Jacobians' nonzeros at a point (or
        widen them over several), and rebuild the solver on the pattern they keep; with
        `barrier`, one that goes on from a run that ended at that barrier parameter."""
        if not self._windows.active:
            return
        if widen:
            self._windows.widen(*map(self._jacobian_values, points))
        else:
            self._windows.fit(self._jacobian_values(points[0]))
        self._make_solver(barrier)

    def _plain_nlp(self, residual: ca.MX, jac: ca.MX, constraint_jac: ca.MX,
                   curvature: ca.Function, small_rows: slice) -> tuple[dict, dict]:
        """The NLP in the decision vector z, objective 0.5 |r(z)|^2, and Ipopt's derivatives.

        Gradient J'r and the Gauss-Newton Hessian J'J from the (compiled)
        residual Jacobian blocks, plus the small constraints' curvature.
        """
        z, empty = self._z, ca.MX.sym("p", 0, 1)
        obj = 0.5 * ca.sumsqr(residual)
        sigma_f = ca.MX.sym("sigma_f")
        lam_g = ca.MX.sym("lam_g", self._g.numel())
        hessian = sigma_f * ca.mtimes(jac.T, jac) + curvature(z, lam_g[small_rows])
        return {"x": z, "f": obj, "g": self._g}, {
            "jac_g": ca.Function("jac_g", [z, empty], [self._g, constraint_jac],
                                 ["x", "p"], ["g", "jac_g_x"]),
            # dense, as Ipopt's interface copies it
            "grad_f": ca.Function("grad_f", [z, empty], [obj, ca.densify(ca.mtimes(jac.T,
                                                                                   residual))],
                                  ["x", "p"], ["f", "grad_f_x"]),
            "hess_lag": ca.Function("gauss_newton", [z, empty, sigma_f, lam_g],
                                    [ca.triu(hessian)], ["x", "p", "lam_f", "lam_g"],
                                    ["hess_gamma_x_x"])}

    def _sensor_blocks(self, step: ca.Function, n: int, h: float
                       ) -> tuple[list[_Block], list[np.ndarray], list[int]]:
        """The per-sample residual functions of every sensor the model observes, and where
        each block's rows go; records `self._samples`, one entry per sensor.

        A sample at a node is predicted from that node's state; a sample between
        nodes one partial RK4 step after the node before it.  Sensors sampled at the
        same times (an IMU and the load cells) share one block, so the step to each
        sample time is taken once for all of them: per such set of times, one block
        of the samples at nodes and one of those between.  The rows of every block
        are instance-major (every channel of one sample, then the next sample);
        `destinations[b]` gives, per row of block b, its row in the sensors' part of
        the residual vector, where sensor j's rows are offsets[j]..offsets[j+1]-1,
        instance-major, in the order of `self._samples`.
        """
        m = self.model
        xs, ts, dts = ca.SX.sym("x", m.nx), ca.SX.sym("t"), ca.SX.sym("dt")
        ps, cs = ca.SX.sym("p", len(m.parameters)), ca.SX.sym("c", len(m.captures))
        self._samples = []
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
            number = len(self._samples)
            self._samples.append((sensor.name, channels, tsamp, meas, sig))
            offsets.append(offsets[-1] + meas.size)
            same = next((members for times, members in groups
                         if np.array_equal(times, tsamp)), None)
            if same is None:
                groups.append((tsamp, [number]))
            else:
                same.append(number)
        blocks, destinations = [], []
        for tsamp, members in groups:
            k = np.clip(np.searchsorted(self.t, tsamp + 1e-7 * h, side="right") - 1, 0, n - 1)
            dt = tsamp - self.t[k]
            between = np.abs(dt) >= 1e-7
            for samples in (np.flatnonzero(~between), np.flatnonzero(between)):
                if samples.size == 0:
                    continue
                names = [self._samples[i][0] for i in members]
                meas = np.vstack([self._samples[i][3][:, samples] for i in members])
                sig = np.vstack([self._samples[i][4][:, samples] for i in members])
                ym, sg = ca.SX.sym("ym", meas.shape[0]), ca.SX.sym("sg", meas.shape[0])
                if between[samples[0]]:
                    x_at, t_at, sym_extra, extra = (step(xs, ts, dts, ps, cs), ts + dts,
                                                    [dts], [dt[samples]])
                else:
                    x_at, t_at, sym_extra, extra = xs, ts, [], []
                y_at = ca.vertcat(*[m.outputs[name](x_at, t_at, ps, cs) for name in names])
                fn = ca.Function(f"residual_{len(blocks)}", [xs, ts, *sym_extra, ym, sg, ps, cs],
                                 [(ym - y_at) / sg])
                blocks.append(_Block(fn, [k[samples]], self.t[k[samples]],
                                     [*extra, meas, sig]))
                # Row (sample j, channel c) of sensor i lies at offsets[i] + j n_i + c.
                destinations.append(np.concatenate([
                    offsets[i] + samples[:, None] * len(self._samples[i][1])
                    + np.arange(len(self._samples[i][1]))[None, :]
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
        """The arguments of `block.fn` for all its instances at once (one column each)."""
        _, Xp, pfull, Cp, _, _ = self._ctx
        return [*(Xp[:, k] for k in block.nodes), ca.DM(block.times).T,
                *(ca.DM(d) if np.ndim(d) == 2 else ca.DM(d).T for d in block.data), pfull, Cp]

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
        return zcols

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
            out = fn.map(n_inst, "thread", 2)(*call)
            return [ca.vec(o) for o in (out if isinstance(out, tuple | list) else [out])]

        with_jacobian, nz = mapped(local)
        zcols = self._instance_columns(block)
        ncols = zcols.shape[1]
        rows = (np.arange(n_inst)[:, None] * mrows + np.arange(mrows)[None, :])
        r_full = np.repeat(rows[:, None, :], ncols, axis=1).reshape(-1)
        c_full = np.repeat(zcols[:, :, None], mrows, axis=2).reshape(-1)
        order = np.lexsort((r_full, c_full))
        n_z = self._ctx[0].numel() + len(self.free) + len(self.model.captures)
        sp = ca.Sparsity.triplet(n_inst * mrows, n_z, r_full[order].tolist(),
                                 c_full[order].tolist())
        return _Piece(mapped(block.fn)[0], mapped(value_fn)[0], with_jacobian,
                      ca.MX(sp, nz[order.tolist()]), np.repeat(block.times, mrows))

    def initial_point(self) -> np.ndarray:
        """Shooting nodes from the kinematic track (GPS, or the altimeter's vertical track) and
        the effects' own state guesses, parameters from the reduction, captures from the
        track's speed."""
        m = self.model
        x0, guessed = self._guessed_states(self.t)
        vel = x0[m.state_slice("velocity")].T
        unguessed = [st for st in m.states if st.name not in guessed]
        if unguessed:
            # States no effect guesses from the data (a Pilot's separation): a forward
            # simulation from the first node with the initial parameter values.
            traj = simulate(m, self.values, x0[:, 0], self.t[0], self.t[-1],
                            step=self.fine_step)
            for st in unguessed:
                rows = m.state_slice(st.name)
                x0[rows] = np.array([np.interp(self.t, traj.t, col) for col in traj.x[:, rows].T])
        p0 = np.array([self.values[f] for f in self.free]) / self.pscale
        # Captured values: each capture's quantity at the guessed state nearest its time
        # (the start airspeeds the captures themselves feed in at the GPS speed).
        speed = np.linalg.norm(vel, axis=1)
        times = [c.at_time if c.at_time is not None else self.values[c.time_parameter]
                 for c in m.captures]
        c_speed = np.interp(times, self.t, speed)
        pvec = m.parameter_vector(self.values)
        c0 = np.empty(len(m.captures))
        for i, (cap, tc) in enumerate(zip(m.captures, times, strict=True)):
            k = int(np.argmin(np.abs(self.t - tc)))
            c0[i] = float(m.capture_function(cap.name)(x0[:, k], self.t[k], pvec, c_speed))
        c0 = np.maximum(c0, [c.lower for c in m.captures]) / self._cscale
        return np.concatenate([(x0 / self._xscale[:, None]).ravel(order="F"), p0, c0])

    def _guessed_states(self, t: np.ndarray) -> tuple[np.ndarray, set[str]]:
        """States at times `t` (nx x len(t)) from the kinematic track (GPS, or the altimeter's
        vertical track) and the effects' own guesses, pinned states at their start values,
        and the names of the states so guessed (the others are zero)."""
        m = self.model
        track = kinematic_track(self.test, t)
        x0 = np.zeros((m.nx, len(t)))
        x0[m.state_slice("position")] = track.position.T
        x0[m.state_slice("velocity")] = track.velocity.T
        guessed = {"position", "velocity"}
        for name, value in self._state_guesses(self.values, t).items():
            x0[m.state_slice(name)] = value
            guessed.add(name)
        for st in m.states:
            if st.pinned:
                x0[m.state_slice(st.name), 0] = st.initial
        return x0, guessed

    def point_from(self, fit: Fit, values: dict[str, float] | None = None) -> np.ndarray:
        """This NLP's decision vector at `fit`, a fit of another model of the same test on
        this grid or a coarser one within it (`_fit_states`): states, parameters and
        captured values by name.

        States the fit's model lacks come from this model's effects' guesses
        (`Effect.state_guess`), else zero; parameters it lacks take this
        estimator's values; `values` (SI) override both.
        """
        fit_x = self._fit_states(fit)
        m = self.model
        known = {**self.values, **{k: v for k, v in fit.parameters.items()
                                   if k in m.parameter_names}, **(values or {})}
        x0 = np.zeros((m.nx, len(self.t)))
        theirs = {st.name for st in fit.model.states}
        for name, guess in self._state_guesses(known, self.t).items():
            if name not in theirs:
                x0[m.state_slice(name)] = guess
        for st in m.states:
            if st.name in theirs:
                x0[m.state_slice(st.name)] = fit_x[:, fit.model.state_slice(st.name)].T
            elif st.pinned:
                x0[m.state_slice(st.name), 0] = st.initial
        p0 = np.array([known[f] for f in self.free]) / self.pscale
        c0 = np.array([fit.captures[c.name] for c in m.captures]) / self._cscale
        return np.concatenate([(x0 / self._xscale[:, None]).ravel(order="F"), p0, c0])

    def extension_start(self, fit: Fit, values: dict[str, float] | None = None
                        ) -> tuple[np.ndarray, tuple[float, float]]:
        """This NLP's start at `fit`, a fit of a model this one extends, with its chi-square
        and largest scaled gap (`evaluate`): `point_from(fit, values)`, with the states
        the fit's model lacks guessed from the data or, where that is nearer feasible,
        integrated through the fitted motion (`swept`).

        On `drogue` flown with added mass and fitted without it, an elastic
        riser's stretch guessed from the measured tension left shooting gaps of
        0.45 (scaled) and chi-square 87,477; integrated, 1.3e-5 and 8,553
        against the fit's 8,518.
        """
        z = self.point_from(fit, values)
        theirs = {st.name for st in fit.model.states}
        new = [st.name for st in self.model.states if st.name not in theirs]
        guessed = self.evaluate(z)
        if not new:
            return z, guessed
        swept = self.swept(z, new)
        integrated = self.evaluate(swept)
        return (swept, integrated) if integrated[1] < guessed[1] else (z, guessed)

    def _fit_states(self, fit: Fit) -> np.ndarray:
        """The fit's states at this grid's nodes (len(t) x the fit's nx): its own nodes, and
        between them (this grid refined, `_stable_grid`) one RK4 step of the fit's model
        from the node before, as its shooting intervals predict."""
        if fit.t.shape == self.t.shape and np.allclose(fit.t, self.t):
            return fit.x
        k = np.clip(np.searchsorted(fit.t, self.t + 1e-9, side="right") - 1, 0, len(fit.t) - 1)
        dt = self.t - fit.t[k]
        inside = np.isin(np.round(fit.t, 6), np.round(self.t, 6))
        if not (np.all(inside) and abs(fit.t[-1] - self.t[-1]) < 1e-6):
            raise ValueError("the fit was made on a shooting grid this one does not refine")
        between = dt > 1e-9
        x = fit.x[k].copy()
        if np.any(between):
            step = rk4_step(fit.model).map(int(between.sum()))
            x[between] = np.asarray(step(
                fit.x[k[between]].T, fit.t[k[between]], dt[between],
                fit.model.parameter_vector(fit.parameters),
                fit.model.capture_vector(fit.captures))).T
        return x

    def swept(self, z: np.ndarray, states: Sequence[str]) -> np.ndarray:
        """`z` with the named states integrated forward along the grid from their first node,
        every other state held at its node values: the named states' shooting gaps close.

        A fit extended by an effect with states of its own starts those states
        from the effect's guesses from the data (`Effect.state_guess`), which
        the fitted trajectory does not carry: with a riser's stretch guessed
        from the measured tension, the null point of the elastic riser on a
        misspecified `drogue` fit opened gaps no solve closed in 500
        iterations.  Integrated through the fitted motion, the states follow it.
        """
        m = self.model
        nx, n = m.nx, len(self.t) - 1
        X = z[:nx * (n + 1)].reshape(n + 1, nx).T * self._xscale[:, None]
        _, pfull, Cp = self._unpack(z)
        rows = np.concatenate([np.arange(nx)[m.state_slice(name)] for name in states])
        sub = self.settings.substeps
        for k in range(n):
            x = X[:, k]
            dt = (self.t[k + 1] - self.t[k]) / sub
            for j in range(sub):
                x = np.asarray(self._step(x, self.t[k] + j * dt, dt, pfull, Cp)).ravel()
            X[rows, k + 1] = x[rows]
        out = z.copy()
        out[:nx * (n + 1)] = (X / self._xscale[:, None]).ravel(order="F")
        return out

    def feasible_point(self, z: np.ndarray) -> tuple[np.ndarray, float] | None:
        """A feasible point near `z` and its chi-square; None where none is found.

        Every state is integrated forward from the first node with the
        parameters at `z` (`swept`), which closes the shooting gaps.  The other
        constraints are then met by alternating with that integration: each
        captured value is set to what the trajectory gives at its event, and
        the parameters take the least-norm (scaled) step that meets the
        effects' own constraints to first order.  None where, after
        FEASIBILITY_SWEEPS, a constraint is still violated by more than
        STOP_CONSTRAINT_TOL: a what-if limit, a trajectory that left the
        model's domain, or a constraint on a captured state (a Pilot's riser
        gap at its start time), which only a change of the trajectory would meet.

        Any feasible point bounds the optimum from above: an unconverged solve's
        last iterate, made feasible this way, gives a lower bound on the
        chi-square a richer model removes (`score_test.confirm`).
        """
        all_states = [st.name for st in self.model.states]
        n_gaps = self.model.nx * (len(self.t) - 1)
        n_states, n_free, ncap = self._nz
        captures = slice(n_states + n_free, n_states + n_free + ncap)
        effect_rows = slice(n_gaps + ncap, n_gaps + ncap + len(self.model.constraints))
        params = self._param_index
        point = self.swept(z, all_states)
        for _ in range(FEASIBILITY_SWEEPS):
            g, A = self._points.constraints(point)
            excess = g - np.clip(g, self._lbg, self._ubg)
            if not np.all(np.isfinite(excess)) \
                    or np.max(np.abs(excess[n_gaps:]), initial=0.0) <= STOP_CONSTRAINT_TOL:
                break
            point = point.copy()
            # Capture rows read C_i - (the trajectory's value at the event) / cscale.
            point[captures] -= excess[n_gaps:n_gaps + ncap]
            if effect_rows.stop > effect_rows.start:
                rows = A[effect_rows][:, params].toarray()
                point[params] -= np.linalg.lstsq(rows, excess[effect_rows], rcond=None)[0]
            point[params] = np.clip(point[params], self._lbz[params], self._ubz[params])
            point = self.swept(point, all_states)
        chi2, violation = self.evaluate(point)
        if not (np.isfinite(chi2) and violation <= STOP_CONSTRAINT_TOL):
            return None
        return point, chi2

    def _state_guesses(self, values: dict[str, float], t: np.ndarray
                       ) -> dict[str, np.ndarray]:
        """The effects' own guesses of their states at times `t` (`Effect.state_guess`)."""
        out: dict[str, np.ndarray] = {}
        for effect in self.model.effects:
            out.update(effect.state_guess(self.test, t, values))
        return out

    # ------------------------------------------------------------------ solve
    def size_text(self) -> str:
        """One line describing the NLP's size."""
        nX, nP, nC = self._nz
        return (f"{nX + nP + nC} variables ({nX} shooting states on {len(self.t)} nodes, "
                f"{nP} parameters, {nC} captured speeds), {self._g.numel()} constraints, "
                f"{sum(len(s_[2]) * len(s_[1]) for s_ in self._samples)} residuals")

    def solve(self, progress: bool = False, start: Fit | np.ndarray | None = None,
              bounds: dict[str, tuple[float, float]] | None = None,
              max_iter: int | None = None, sensitivities: bool = True) -> Fit:
        """Solve the NLP; raise SolverFailure if it fails.

        It starts from the reduction's initial point, from the solution of
        `start` (a fit of this same estimator) or from `start` itself (a
        decision vector, e.g. `point_from`).  `bounds` replaces the bounds of
        free parameters (SI; equal bounds pin a value): a what-if constraint.
        The fit then reports, per bounded parameter, the sensitivity of the
        optimal chi-square to the bound, d(chi^2)/d(value) (its Lagrange
        multiplier, times 2, per SI unit).
        With `progress`, a one-line iteration counter with chi-square is shown on stderr.
        `max_iter` stops this solve after fewer iterations than the settings' limit.
        Without `sensitivities` (a profile's points, a null point: values held, their
        multipliers unused) a run that stalls goes on by feasible Gauss-Newton steps as an
        unbounded one does: a held point of the main's expopen on the Prometheus TeleMega
        log with the wind process took 26 iterations (8.9 s) that way, against 500 iterations
        (135 s) of Ipopt cycling within 1.2 of its chi-square without
        (`benchmarks/fill_resolution.py`; on the TeleMetrum log neither converged until
        the descent learnt the curvature, `Settings.descent_curvature`).
        """
        z0 = (self.initial_point() if start is None
              else start.z if isinstance(start, Fit) else np.asarray(start, dtype=float))
        lbz, ubz = self._lbz.copy(), self._ubz.copy()
        n_states = self._nz[0]
        for name, (lo, hi) in (bounds or {}).items():
            i = self.free.index(name)
            lbz[n_states + i], ubz[n_states + i] = lo / self.pscale[i], hi / self.pscale[i]
        z0 = np.clip(z0, lbz, ubz)
        t0 = time.perf_counter()
        cap = min(max_iter or self.settings.max_iter, self.settings.max_iter)
        self._fit_windows(z0)
        if self._warm:  # an earlier solve's restart left its warm-started solver behind
            self._make_solver()
        iterations = 0
        multipliers: dict[str, ca.DM] = {}
        descended: DescentEnd | None = None
        # A what-if's sensitivities need Ipopt's own multipliers at its own solution.
        stall = not bounds or not sensitivities
        while True:
            self._monitor.reset(progress, (lbz, ubz), cap - iterations, iterations, stall)
            with interrupts.deferred():  # a signal stops Ipopt at its next iteration
                sol = self._solver(x0=z0, lbx=lbz, ubx=ubz, lbg=self._lbg, ubg=self._ubg,
                                   **multipliers)
            st = self._solver.stats()
            iterations += int(st["iter_count"])
            z0 = np.asarray(sol["x"]).ravel()
            multipliers = {"lam_x0": sol["lam_x"], "lam_g0": sol["lam_g"]}
            # No iteration record where Ipopt stopped at its first evaluation (a NaN there).
            mu = st.get("iterations", {}).get("mu", [])
            barrier = float(mu[-1]) if len(mu) else None
            left = self._monitor.left_at
            if self._monitor.stalled:
                descended = self._descend(z0, (lbz, ubz), cap - iterations)
                iterations += descended.steps if descended is not None else 0
                if (descended is not None and descended.converged) or iterations >= cap:
                    break
                # Not finished that way: Ipopt goes on from its iterate, no longer stopped
                # for stalling.
                if descended is not None and descended.steps:
                    self._monitor.offer(descended.z, descended.chi2)
                stall = False
                self._make_solver(barrier)
                continue
            if left is None and st["success"] and self._windows.active \
                    and self._windows.outside_at(self._jacobian_values(z0)):
                # What Ipopt converged on must hold with every entry: a parameter that
                # acts outside its window at the end sends the run on.
                left = z0
            if left is None or self._monitor.capped or iterations >= cap:
                break
            # A parameter acts outside its window (a start time moved further than the
            # margin): widen the windows over both points and go on from the iterate,
            # with its multipliers and barrier parameter (from the default barrier and
            # least-squares multipliers, the first steps of the new run were regularised
            # and cut: on `drogue_full` 35 iterations in all against 30).
            self._fit_windows(left, z0, widen=True, barrier=barrier)
        self._monitor.finish()
        z = np.asarray(sol["x"]).ravel()
        multipliers = np.asarray(sol["lam_g"]).ravel()
        status, success = self._run_status(st, left is not None)
        decrement = self._monitor.decrement if self._monitor.stopped else None
        own_point = self._monitor.stopped and self._monitor.point is not None
        if own_point:
            # The statistical test ended the run at its own Gauss-Newton step's end.
            z = self._monitor.point
        if descended is not None and descended.converged:
            z, own_point, decrement = descended.z, True, descended.decrement
            status, success = DESCENT_CONVERGED, True
        if own_point or not success:
            # Evaluated here: Ipopt's values describe its last iterate, and after a failure
            # can be placeholders (zeros after an invalid number).
            r = self._points.residual_value(z)
            objective = 0.5 * float(r @ r)
            g = self._points.constraint_value(z)
        else:
            g, objective = np.asarray(sol["g"]).ravel(), float(sol["f"])
        wall = time.perf_counter() - t0
        viol = self._violations(g)
        worst = f"index {int(np.argmax(viol))}, violation {float(np.max(viol)):.3g}" \
            if viol.size else ""
        stats = SolverStats(status, success, iterations, wall, objective, worst, decrement,
                            "the offline reduction" if start is None else
                            "a fit" if isinstance(start, Fit) else "a given point")
        if not stats.success:
            raise SolverFailure(stats.status, stats.iterations, worst, 2.0 * stats.objective,
                                self._last_iterate(z, stats))
        fit = self._fit(z, stats)
        fit.multipliers = multipliers
        if bounds and sensitivities:
            fit.sensitivities = self._bound_sensitivities(z, multipliers, list(bounds))
        return fit

    def _run_status(self, stats: dict, windows_unsettled: bool) -> tuple[str, bool]:
        """The run's status and success from Ipopt's `stats` and the monitor: a stop the
        monitor asked for is named for its reason."""
        status, success = stats["return_status"], bool(stats["success"])
        if windows_unsettled:  # the iterations ran out before the windows held
            return "Maximum_Iterations_Exceeded", False
        if status == "User_Requested_Stop" and self._monitor.stopped:
            return STATISTICALLY_CONVERGED, True
        if status == "User_Requested_Stop" and self._monitor.capped:
            return "Maximum_Iterations_Exceeded", False
        if status == "User_Requested_Stop" and self._monitor.diverged:
            return "Diverging_Iterates", False
        if status == "User_Requested_Stop" and self._monitor.stalled:
            return STALLED, False
        return status, success

    def _descend(self, z: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], left: int
                 ) -> DescentEnd | None:
        """Gauss-Newton steps through feasible points (`feasible_descent`) within the scaled
        `bounds`, at most `descent_steps` of them and the `left` iterations of the run's
        cap, from the feasible point nearest the stalled iterate `z` or the run's lowest
        nearly feasible iterate, whichever has the lower chi-square; None where the
        settings allow none (a what-if limit, no statistical test) or neither has a
        feasible point near it.

        Ipopt had stopped making progress: on `drogue` flown with added mass and
        refitted with elastic risers instead, its iterate after 30 iterations
        (chi-square 8,064.7, made feasible) reached the statistical test's
        tolerance in 8 such steps (8,033.8, 5.6 s), where Ipopt had not in 150
        iterations.  Ipopt's iterate can lie far below its best nearly feasible
        one, which may be the start: it moves through infeasible points.
        """
        tol = self.settings.chi2_step_tol
        if self.settings.descent_steps <= 0 or not tol or self._has_inequalities:
            return None
        points = [self.feasible_point(x) for x in (z, self._monitor.best) if x is not None]
        points = [p for p in points if p is not None]
        if not points:
            return None
        start = min(points, key=lambda p: p[1])
        idx = self._param_index
        lower, upper = bounds
        problem = DescentProblem(self._linearize, self.feasible_point,
                                 self._points.residual_value, idx, lower[idx], upper[idx])
        learn = self.settings.descent_curvature
        return descend(*start, problem, tol, min(self.settings.descent_steps, left), learn)

    @property
    def best_iterate(self) -> np.ndarray | None:
        """The last solve's nearly feasible iterate (constraints within
        POLISH_CONSTRAINT_TOL, scaled) with the lowest chi-square, None if it had none:
        where a run that did not converge came closest, which its last iterate (a
        watchdog's trial step, say) need not be."""
        return self._monitor.best

    def _last_iterate(self, z: np.ndarray, stats: SolverStats) -> Fit | None:
        """The Fit at an unconverged solve's last iterate, for its failure report only
        (None where the iterate cannot even be evaluated)."""
        if not np.all(np.isfinite(z)):
            return None
        try:
            return self._fit(z, stats)
        except (RuntimeError, ValueError):
            return None

    def _bound_sensitivities(self, z: np.ndarray, lam_g: np.ndarray,
                             names: list[str]) -> dict[str, float]:
        """d(chi^2)/d(value) of each bounded parameter at a solution: twice the gradient of
        the Lagrangian of the other constraints in that parameter (SI units)."""
        r, jac = self._points.residual_jacobian(z)
        _, jac_g = self._points.constraints(z)
        grad = jac.T @ r + jac_g.T @ lam_g
        n_states = self._nz[0]
        return {n: float(2.0 * grad[n_states + self.free.index(n)]
                         / self.pscale[self.free.index(n)]) for n in names}

    def _stop_test(self, z: np.ndarray) -> tuple[float, np.ndarray] | None:
        """The point at which the statistical test may end the run, near the Ipopt iterate
        `z`, and the Gauss-Newton chi-square decrement there; None if there is none.

        The point must be feasible, in two senses: every scaled constraint
        within STOP_CONSTRAINT_TOL (the shooting gaps then below 1 mm and
        0.1 mm/s), evaluated here rather than taken from Ipopt, whose reported
        values may be scaled; and closing what gaps remain, with the
        parameters held, changes chi-square by less than the test's own
        tolerance (`GaussNewtonStep.restoration`: tiny gaps on many intervals
        add up).  An iterate that misses either but whose gaps are within
        POLISH_CONSTRAINT_TOL is offered one full Gauss-Newton step (the
        linearised constraints hold after it, so what remains of the gaps is
        second order in the step) and a few more (`_finishing_steps`); a
        step's end is the point if it is feasible and within the bounds, else
        its feasible projection or the iterate's may be.  Near the optimum Ipopt
        shrinks the gaps only linearly, by the same factor as its steps, several
        iterations for what one step does.
        """
        tol = self.settings.chi2_step_tol or 0.0
        lin = self._linearize(z)
        violation = _violation(lin)
        # An inequality (a what-if limit) inactive at z might be crossed by the finishing
        # step unseen: the linearisation holds only the active ones.
        may_polish = (self.settings.polish and violation <= POLISH_CONSTRAINT_TOL
                      and not self._has_inequalities)
        if violation > STOP_CONSTRAINT_TOL and not may_polish:
            return None  # no Gauss-Newton solve for an iterate that cannot end the run
        gn = gauss_newton(lin)
        self._monitor.promised = gn.decrement
        found = None  # (decrement, point) that sets the tests' back-off
        if violation <= STOP_CONSTRAINT_TOL and abs(gn.restoration) <= tol:
            found = self._measured_decrement(lin, gn), z
            if found[0] < tol or not may_polish:
                return found
        if not may_polish:
            return None
        stop, first = self._finishing_steps(lin, gn, tol)
        if stop is not None:
            return stop
        found = found or first
        if found is None and violation > STOP_CONSTRAINT_TOL:
            # The iterate's feasible projection: it ends the run or counts for nothing.
            lower, upper = self._monitor.bounds
            projection = self._candidate(z + gn.projection, lower, upper, STOP_CONSTRAINT_TOL)
            if projection is not None and self._feasible(projection, tol):
                decrement = self._measured_decrement(*projection)
                if decrement < tol:
                    return decrement, projection[0].z
        return found

    def _finishing_steps(self, lin: Linearization, gn: GaussNewtonStep, tol: float
                         ) -> tuple[tuple[float, np.ndarray] | None,
                                    tuple[float, np.ndarray] | None]:
        """Up to FINISHING_STEPS Gauss-Newton steps of the estimator's own from `lin`'s
        point: (decrement, point) where one ends the run, else None; and the first
        step's end with its decrement if that end is feasible as it stands.

        Each step's end is projected onto the gaps where it misses them (a Newton
        step on the gaps with the parameters held closes them quadratically, where
        the step's nonlinearity leaves them open: on `drogue_full` a step that
        travelled far along a weakly determined direction closed 1.5e-4 only to
        5e-5).  After the first full step each is shortened to where chi-square is
        least along it (a = D / c, the curvature c measured by
        `_measured_decrement`): the Gauss-Newton model leaves out the shooting
        gaps' curvature, and full steps did not converge (on `drogue`, from
        decrements of 0.46, 0.17 and 0.10, a second full step reached 0.71, 0.24
        and 0.18).  Ipopt's own iterate is held off the optimum by the barrier of
        the parameters' bounds and by that curvature: on `drogue` from the
        reduction it sat a decrement of 6.4 from the optimum at the third
        iteration and crept after it for 23 more; after its first iteration these
        steps reached 1.18, 0.064 and then 0.009, which ends the run.  A step that
        does not halve the decrement leaves the run to Ipopt.

        The decrement is measured along a direction that leaves that curvature
        out, so a point just below the tolerance may lie a little more than it
        above the optimum (0.0102 against a tolerance of 0.01 on `drogue`, seed
        1): where a step's end ends the run, one more step is taken, and kept
        where its decrement is lower.  Only the first step's end, unprojected,
        may set the tests' back-off: the decrement at a projection or after
        several steps ends the run or counts for nothing (on `fbcp` a
        projection's put off the test that ends the run by three iterations).
        """
        lower, upper = self._monitor.bounds
        first = stop = None
        point, last, length = (lin, gn), np.inf, 1.0
        for k in range(FINISHING_STEPS + 1):
            end = self._candidate(point[0].z + length * point[1].step, lower, upper,
                                  POLISH_CONSTRAINT_TOL)
            projected = end is not None and not self._feasible(end, tol)
            if projected:
                end = self._candidate(end[0].z + end[1].projection, lower, upper,
                                      STOP_CONSTRAINT_TOL)
            if end is None or not self._feasible(end, tol):
                break
            decrement = self._measured_decrement(*end)
            if stop is not None:  # the polishing step: kept where it got closer
                if decrement < stop[0]:
                    stop = decrement, end[0].z
                break
            if decrement < tol:
                stop = decrement, end[0].z
            elif k == FINISHING_STEPS - 1 or not decrement < 0.5 * last:
                break
            if k == 0 and not projected:
                first = decrement, end[0].z
            point, last = end, decrement
            length = min(1.0, decrement / max(end[1].decrement, DECREMENT_FLOOR))
        return stop, first

    @staticmethod
    def _feasible(candidate: tuple[Linearization, GaussNewtonStep], tol: float) -> bool:
        """Whether a candidate's point meets STOP_CONSTRAINT_TOL and closing its remaining
        gaps is worth less than `tol` in chi-square."""
        lin, gn = candidate
        return _violation(lin) <= STOP_CONSTRAINT_TOL and abs(gn.restoration) <= tol

    def _candidate(self, z: np.ndarray, lower: np.ndarray, upper: np.ndarray, limit: float
                   ) -> tuple[Linearization, GaussNewtonStep] | None:
        """The linearisation and Gauss-Newton step at a point where the run might stop, if it
        lies within the bounds and its scaled constraints within `limit` (judged on their
        values first: 3 ms on `drogue`, where a linearisation takes 70)."""
        if np.any(z < lower) or np.any(z > upper) \
                or not self._value_violation(z) <= limit:  # NaN too
            return None
        lin = self._linearize(z)
        return lin, gauss_newton(lin)

    def _measured_decrement(self, lin: Linearization, gn: GaussNewtonStep) -> float:
        """The chi-square decrease still to be had along `gn` from `lin.z`, its curvature
        measured (`uncertainty.measured_decrement`)."""
        return measured_decrement(self._points.residual_value, lin, gn)

    def covariance(self, fit: Fit, scale_by_residual: bool = False,
                   hessian: str = "gauss-newton") -> Covariance:
        """Covariance of the free parameters at `fit`: the KKT system's parameter block.

        `hessian` is "gauss-newton" (J'J of the weighted residuals) or "exact"
        (the Hessian of the Lagrangian at the fit's multipliers; see
        `uncertainty`).  `scale_by_residual` multiplies it by chi^2/dof, for
        sensor sigmas that are not trusted.
        """
        if hessian not in HESSIANS:
            raise ValueError(f"hessian must be one of {HESSIANS}; got {hessian!r}")
        product = None
        if hessian == "exact":
            fn = self._lagrangian_hessian_product()
            product = lambda Z: np.asarray(  # noqa: E731
                fn.map(Z.shape[1], "serial")(fit.z, fit.multipliers, Z))
        return kkt_covariance(self._linearize(fit.z), self._param_index, self.pscale,
                              self.free, scale_by_residual, product)

    def _violations(self, g: np.ndarray) -> np.ndarray:
        """How far each constraint value in `g` lies outside its bounds (scaled)."""
        return np.maximum(self._lbg - g, 0) + np.maximum(g - self._ubg, 0)

    def _value_violation(self, z: np.ndarray) -> float:
        """Largest scaled constraint violation at `z`, from the constraint values alone (the
        same figure as `_violation` of the linearisation there; NaN where not finite)."""
        g = self._points.constraint_value(z)
        if not np.all(np.isfinite(g)):
            return np.nan
        return float(np.max(self._violations(g), initial=0.0))

    def evaluate(self, z: np.ndarray) -> tuple[float, float]:
        """Chi-square at the decision vector `z` and its largest scaled constraint violation
        (the shooting gaps in units of the state scales)."""
        lin = self._linearize(z)
        return float(lin.r @ lin.r), _violation(lin)

    def gauss_newton_estimate(self, z: np.ndarray, release: Sequence[str] = ()
                              ) -> tuple[dict[str, float], Covariance]:
        """The free parameters after one Gauss-Newton step from `z` (SI), and their covariance
        there; parameters in `release` are treated as unbounded (see `_linearize`).

        At the optimum of a model with some parameters held at null values, the
        step's components along them are their linearised estimates (`score_test`).
        """
        lin = self._linearize(z, release)
        cov = kkt_covariance(lin, self._param_index, self.pscale, self.free)
        return self.free_values(z + gauss_newton_step(lin)), cov

    def information_log_det(self, fit: Fit) -> float:
        """log det of the Gauss-Newton information of every free coordinate at `fit`, in the
        scaled decision vector (`uncertainty.log_det_information`): the volume term of a
        Laplace approximation (`process_intensity`)."""
        return log_det_information(self._linearize(fit.z))

    def gauss_newton_point(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """The end of one full Gauss-Newton step from the decision vector `z` (the linearised
        constraints met there), clipped into the variables' bounds, and the chi-square
        at `z`: both from one linearisation."""
        lin = self._linearize(z)
        step_end = np.clip(z + gauss_newton_step(lin), self._lbz, self._ubz)
        return step_end, float(lin.r @ lin.r)

    def with_value(self, z: np.ndarray, name: str, value: float) -> np.ndarray:
        """A copy of the decision vector `z` with the free parameter `name` at `value` (SI)."""
        i = self.free.index(name)
        out = z.copy()
        out[self._param_index[i]] = value / self.pscale[i]
        return out

    def free_values(self, z: np.ndarray) -> dict[str, float]:
        """The free parameters at the decision vector `z` (SI)."""
        values = z[self._param_index] * self.pscale
        return dict(zip(self.free, map(float, values), strict=True))

    def _lagrangian_hessian_product(self) -> ca.Function:
        """(z, lambda, v) -> H v, H the Hessian of 0.5 |r|^2 + lambda' g in the scaled z
        (forward over reverse mode on the NLP's expression graph; built on first use)."""
        if self._hessian_product is None:
            lam = ca.MX.sym("lam", self._g.numel())
            v = ca.MX.sym("v", self._z.numel())
            grad = ca.gradient(self._obj + ca.dot(lam, self._g), self._z)
            self._hessian_product = ca.Function("hessian_product", [self._z, lam, v],
                                                [ca.jtimes(grad, self._z, v)])
        return self._hessian_product

    @property
    def _param_index(self) -> np.ndarray:
        nX, nP, _ = self._nz
        return np.arange(nX, nX + nP)

    def _linearize(self, z: np.ndarray, release: Sequence[str] = ()) -> Linearization:
        """The problem linearised at `z`; the free parameters named in `release` are treated
        as unbounded (a score test's parameters sit on a bound at their null values)."""
        idx = self._param_index
        nx = self.model.nx
        n_states = self._nz[0]
        pinned = np.flatnonzero(self._lbz[:nx] == self._ubz[:nx])
        lower, upper = self._lbz[idx].copy(), self._ubz[idx].copy()
        for name in release:
            i = self.free.index(name)
            lower[i], upper[i] = -np.inf, np.inf
        points = self._points
        return linearize(points.residual_jacobian, points.constraints, z, self._lbg, self._ubg,
                         idx, lower, upper, chain_rows=n_states - nx,
                         dependent=np.arange(nx, n_states), pinned=pinned)

    def _fit(self, z: np.ndarray, stats: SolverStats) -> Fit:
        m = self.model
        Xp, pfull, Cp = (np.asarray(a) for a in self._unpack(z))
        params = {p.name: float(v) for p, v in zip(m.parameters, pfull.ravel(), strict=True)}
        caps = {c.name: float(v) for c, v in zip(m.captures, Cp.ravel(), strict=True)}
        blocks = self._residuals(z)
        blocks = blocks if isinstance(blocks, tuple | list) else [blocks]
        residuals = []
        for (sensor, channels, tsamp, meas, sig), r in zip(self._samples, blocks, strict=True):
            # Residual blocks are instance-major: (meas - model) / sigma per sample.
            r = np.asarray(r).reshape(len(tsamp), len(channels)).T
            y = meas - r * sig
            for j, ch in enumerate(channels):
                residuals.append(SensorResidual(sensor, ch, tsamp, meas[j], y[j], sig[j]))
        return Fit(self.test, m, params, list(self.free), dict(self.guess), self.t, Xp.T, caps,
                   residuals, stats, self.settings, z)


class _Monitor(ca.Callback):
    """Ipopt iteration callback: progress line on stderr, and the statistical stopping test.

    Gauss-Newton converges linearly, so Ipopt's optimality tests keep it
    polishing chi-square in its fifth decimal long after the estimate has
    stopped moving on the scale of its own uncertainty.  Whenever an
    iteration lowers chi-square by less than `tol`, the monitor asks
    `test(z)` for a feasible point at or one Gauss-Newton step from the
    iterate and the chi-square decrease the full Gauss-Newton step predicts
    there, and stops the run at that point (`point`) once it is below `tol`.
    Each test costs a KKT factorisation (about two iterations' time), so
    tests are at least 3 iterations apart, and 6 then 12 while the decrement
    stays above 10 tol.
    """

    def __init__(self, nx: int, ng: int, violations: Callable[[np.ndarray], np.ndarray],
                 test: Callable[[np.ndarray], tuple[float, np.ndarray] | None],
                 tol: float | None, damping: MarquardtDamping | None = None,
                 stall: int | None = None) -> None:
        ca.Callback.__init__(self)
        self._stall = stall  # iterations without progress that stop a run (None: never)
        self._violations = violations  # how far each constraint value lies outside its bounds
        self._nx, self._ng, self._test, self._tol = nx, ng, test, tol
        self._damping = damping
        self.reset(False, (np.full(nx, -np.inf), np.full(nx, np.inf)))
        self.construct("monitor", {})

    def reset(self, progress: bool, bounds: tuple[np.ndarray, np.ndarray],
              max_iter: int | None = None, done: int = 0, stall: bool = True) -> None:
        """Start a run within `bounds` (the scaled decision vector's lower and upper),
        stopped after `max_iter` iterations if given; `done` iterations were made before
        it (a restart with wider windows of action, or after a stall, which keeps the
        Marquardt damping the run had reached); stopped where it stalls if `stall` and
        the monitor was made to."""
        self._k, self._last_test, self._gap, self._chi2 = 0, -100, 3, np.inf
        self._done = done
        self._outside = 0  # successive iterates with a parameter acting outside its window
        self.left_at: np.ndarray | None = None  # where that has persisted
        self.stopped, self.decrement = False, None
        self.max_iter, self.capped = max_iter, False
        self.diverged = self.stalled = False
        self._stalls = stall and self._stall is not None
        self.point: np.ndarray | None = None  # where the statistical test ended the run
        self.bounds = bounds
        self.progress = progress and sys.stderr.isatty()
        if done:
            return  # a widening restart goes on with what the run had gathered
        if self._damping is not None:
            self._damping.reset()
        self._first_chi2: float | None = None  # the run's first iterate's (divergence)
        # The nearly feasible iterate with the lowest chi-square so far (constraints
        # within POLISH_CONSTRAINT_TOL): an unconverged run's best witness.
        self.best: np.ndarray | None = None
        self._best_chi2 = np.inf
        # The lowest nearly feasible chi-square when it last fell by enough to count as
        # progress (see STALL_ITERATIONS), and the iteration then.
        self._progress = (np.inf, 0)
        # The Gauss-Newton decrement the statistical test last found at an iterate.
        self.promised = 0.0

    def offer(self, z: np.ndarray, chi2: float) -> None:
        """A feasible point found outside the run, kept as its best iterate where lower."""
        if chi2 < self._best_chi2:
            self.best, self._best_chi2 = z, chi2

    def finish(self) -> None:
        if self.progress and self._k + self._done:
            sys.stderr.write("\n")

    # Successive iterates at which some parameter acts outside the window of action
    # Ipopt's derivatives were given before the run is stopped to widen the windows.  A
    # watchdog's trial steps (up to 3) can take the iterate far afield and back: on an
    # elastic-riser refit a restart from such an excursion (chi-square 2e8 against 8,500)
    # started the refit over.
    OUTSIDE_PERSISTS = 4

    def window_check(self, z: np.ndarray, outside: bool) -> None:
        """Whether at the iterate `z` a parameter acts outside its window of action; once
        that has persisted over OUTSIDE_PERSISTS iterates, the run stops at the next
        (and the solve restarts with wider windows from it)."""
        self._outside = self._outside + 1 if outside else 0
        if self._outside >= self.OUTSIDE_PERSISTS and self.left_at is None:
            self.left_at = np.array(z, dtype=float)

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        name = ca.nlpsol_out(i)
        n = {"f": 1, "x": self._nx, "lam_x": self._nx, "g": self._ng, "lam_g": self._ng}.get(
            name, 0)
        return ca.Sparsity.dense(n, 1)

    def eval(self, arg: list) -> list:
        self._k += 1
        if interrupts.pending():
            return [1]  # `interrupts.deferred` raises once Ipopt has returned
        if self.max_iter is not None and self._k > self.max_iter:
            self.capped = True  # called at iterations 0, 1, ...: this is iteration max_iter
            return [1]
        if self.left_at is not None:
            return [1]
        chi2 = 2.0 * float(arg[1])
        if self._first_chi2 is None:
            self._first_chi2 = chi2
        if not chi2 <= DIVERGED_FACTOR * self._first_chi2:  # NaN too
            self.diverged = True
            return [1]
        g = np.asarray(arg[2]).ravel()
        if np.max(self._violations(g), initial=0.0) <= POLISH_CONSTRAINT_TOL:  # not NaN
            if chi2 < self._best_chi2:
                self.best, self._best_chi2 = np.asarray(arg[0]).ravel().copy(), chi2
            if self._best_chi2 <= self._progress[0] - max(STALL_GAIN, STALL_SHARE * self.promised):
                self._progress = (self._best_chi2, self._done + self._k)
        if self._stalls and self.best is not None \
                and self._done + self._k - self._progress[1] >= self._stall:
            self.stalled = True
            return [1]
        if self._damping is not None:
            self._damping.observe(np.asarray(arg[0]).ravel())
        if self.progress:
            sys.stderr.write(f"\r  iteration {self._done + self._k:4d}   "
                             f"chi-square {chi2:14.6g}")
            sys.stderr.flush()
        improved, self._chi2 = self._chi2 - chi2, chi2
        if self._tol is None or improved >= self._tol or self._k - self._last_test < self._gap:
            return [0]
        self._last_test = self._k
        found = self._test(np.asarray(arg[0]).ravel())
        if found is not None:
            d, point = found
            self.decrement = d
            self.stopped = d < self._tol
            self.point = point if self.stopped else None
            # Still far: back off (3, 6, 12 iterations) while the estimate travels.
            self._gap = min(2 * self._gap, 12) if d > 10 * self._tol else 3
        return [1 if self.stopped else 0]


# An accepted iterate whose chi-square exceeds the run's first by this factor (or is not a
# number) ends the run as diverged.  Ipopt's watchdog accepts its trial steps on trust: on
# `drogue` with added mass hidden, an elastic-riser refit's second trial step reached
# chi-square 4e40 from 1.7e4, and the next iteration did not end in two minutes.  Trial
# steps that came back had gone to 1e8 from 8.5e3.
DIVERGED_FACTOR = 1e6

# A run whose lowest nearly feasible chi-square has not fallen by STALL_SHARE of the
# Gauss-Newton decrement the statistical test last found (at least STALL_GAIN) in
# STALL_ITERATIONS iterations is stopped as stalled: Ipopt then gains less in many steps
# than one Gauss-Newton step promises.  Gauss-Newton steps through feasible points
# (`feasible_descent`) finish it where they can.  On `drogue` flown with added mass and
# refitted with elastic risers instead, Ipopt reached chi-square 8,062 by iteration 26
# and crept to 8,060 at its 150-iteration cap, with decrements of 10-25 throughout.  A
# share of one half stopped a fit of `drogue` with a deployment load from the reduction
# at chi-square 78,604 (a fall of 18,100 in 20 iterations against a decrement of 36,500),
# and the descent from there ended in a minimum of its own at 65,190, where Ipopt goes on
# to 7,200.
STALL_ITERATIONS = 20
STALL_SHARE = 0.1
STALL_GAIN = 1.0


def _violation(lin: Linearization) -> float:
    """Largest scaled constraint violation of a linearisation's point (0 without any)."""
    return float(np.max(np.abs(lin.c))) if lin.c.size else 0.0


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

    @classmethod
    def of(cls, expr: ca.MX, z: ca.MX) -> _Piece:
        """A small expression: one graph for its values, CasADi's Jacobian for the rest (its
        rows belong to no time)."""
        return cls(expr, expr, expr, ca.jacobian(expr, z), np.full(expr.numel(), np.nan))


def _stack(pieces: Sequence[_Piece], field_name: str) -> ca.MX:
    """One field of every piece, stacked."""
    return ca.vertcat(*[getattr(p, field_name) for p in pieces])


def _gathered(pieces: Sequence[_Piece], destinations: Sequence[np.ndarray],
              offsets: Sequence[int]) -> list[_Piece]:
    """Row i of `pieces[b]` moved to row `destinations[b][i]` of the stacked result (the
    destinations cover 0..offsets[-1]-1 once), cut into one piece per range
    offsets[j]..offsets[j+1]."""
    if not pieces:
        return []
    order = np.argsort(np.concatenate(destinations))  # stacked row of each result row
    stacked = [_stack(pieces, f) for f in ("symbolic", "value", "with_jacobian", "jacobian")]
    times = _stack_times(pieces)
    out = []
    for a, b in itertools.pairwise(offsets):
        rows = order[a:b].tolist()
        out.append(_Piece(*(x[rows] for x in stacked[:3]), stacked[3][rows, :],
                          times[order[a:b]]))
    return out


def _stack_times(pieces: Sequence[_Piece]) -> np.ndarray:
    """The row times of every piece, stacked."""
    return np.concatenate([p.times for p in pieces]) if pieces else np.zeros(0)


def cubic_bspline(u: ca.MX) -> ca.MX:
    """Cubic B-spline kernel (support |u| < 2, C2, a partition of unity on integer nodes)."""
    a = ca.fabs(u)
    return ca.if_else(a < 1.0, (4.0 - 6.0 * a**2 + 3.0 * a**3) / 6.0,
                      ca.if_else(a < 2.0, (2.0 - a) ** 3 / 6.0, 0.0))


def reconstruct(test: FlightTest, effects: Sequence[Effect] | ModelSpec | None = None,
                settings: Settings | None = None) -> Fit:
    """Reconstruct one test phase: build the NLP, solve it, return the Fit."""
    return Estimator(test, effects, settings).solve()
