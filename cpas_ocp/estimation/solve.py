"""The solve and its stopping rule (`Estimator`'s Ipopt part).

Ipopt on the transcribed NLP, with the statistical test that ends a run once the
Gauss-Newton step would lower chi-square by less than `Settings.chi2_step_tol`, the
finishing steps of a nearly feasible run, and the feasible descent after a stall.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from cpas_ocp import interrupts
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.feasible_descent import DescentEnd, DescentProblem, descend
from cpas_ocp.estimation.fit import (
    FROM_REDUCTION,
    POLISH_CONSTRAINT_TOL,
    STOP_CONSTRAINT_TOL,
    Fit,
    SolverStats,
)
from cpas_ocp.estimation.gauss_newton import (
    DECREMENT_FLOOR,
    GaussNewtonStep,
    bound_reached,
    gauss_newton,
    measured_decrement,
)
from cpas_ocp.estimation.kkt_system import Linearisation
from cpas_ocp.estimation.linearisation import Linearisations
from cpas_ocp.estimation.nlp_functions import (
    MarquardtDamping,
    ipopt_functions,
    worst_violation,
)
from cpas_ocp.estimation.starting_points import StartingPoints
from cpas_ocp.estimation.transcription import Transcription

# Status of a run ended by the statistical test (`Settings.chi2_step_tol`).
STATISTICALLY_CONVERGED = "Solved_Gauss_Newton_Step_Below_Tolerance"


# Status of a run stopped because chi-square no longer fell (`STALL_ITERATIONS`), and of
# one such that Gauss-Newton steps through feasible points finished at the statistical
# test (`feasible_descent`).
STALLED = "Stalled_Without_Progress"


DESCENT_CONVERGED = "Solved_Feasible_Descent_After_Stall"




# Gauss-Newton steps the statistical test may take of its own from an iterate before
# it has a point to end the run at (`Solver._finishing_steps`); one more polishes it.
FINISHING_STEPS = 3


# Where stderr is not a terminal (a pipe, a log file), a progress line is written at most
# this often (s): a long solve shows that it goes on, a short one says nothing.
PIPED_PROGRESS_S = 10.0


class IterationMonitor(ca.Callback):
    """Ipopt iteration callback: progress on stderr, and the statistical stopping test.

    Progress on a terminal is one line redrawn at every iteration (iteration and
    chi-square); where stderr is not a terminal, a whole line is written at most
    every PIPED_PROGRESS_S seconds of the run (with the seconds since it began),
    so that a piped or logged run is not silent through a long solve.

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
        self.violations = violations  # how far each constraint value lies outside its bounds
        self._nx, self._ng, self._test, self._tol = nx, ng, test, tol
        self.damping = damping
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
        self.progress = progress
        self._tty = sys.stderr.isatty()
        self._said = time.monotonic()
        if done:
            return  # a widening restart goes on with what the run had gathered
        self._started = self._said
        if self.damping is not None:
            self.damping.reset()
        self._first_chi2: float | None = None  # the run's first iterate's (divergence)
        # The nearly feasible iterate with the lowest chi-square so far (constraints
        # within POLISH_CONSTRAINT_TOL): an unconverged run's best witness.
        self.best: np.ndarray | None = None
        self._best_chi2 = np.inf
        # The lowest nearly feasible chi-square when it last fell by enough to count as
        # progress (see STALL_ITERATIONS), and the iteration then.
        self._progress = (np.inf, 0)
        self._after_descent = False  # counting since a descent that did not finish the run
        # The Gauss-Newton decrement the statistical test last found at an iterate.
        self.promised = 0.0

    def count_progress_from(self, iteration: int) -> None:
        """Count the iterations without progress afresh from `iteration`, from the lowest
        nearly feasible chi-square found so far, for a run that goes on after a descent
        that did not finish it: it stalls again only where that falls by less than
        STALL_GAIN in AFTER_DESCENT_STALLS times STALL_ITERATIONS iterations (the
        Gauss-Newton decrement last found, measured before the descent, no longer sets
        what counts as progress)."""
        self._progress = (self._best_chi2, iteration)
        self._after_descent = True

    @property
    def best_chi2(self) -> float:
        """The chi-square of `best` (inf where there is none)."""
        return self._best_chi2

    def offer(self, z: np.ndarray, chi2: float) -> None:
        """A feasible point found outside the run, kept as its best iterate where lower."""
        if chi2 < self._best_chi2:
            self.best, self._best_chi2 = z, chi2

    def finish(self) -> None:
        if self.progress and self._tty and self._k + self._done:
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

    def show(self, iteration: int, chi2: float, what: str = "iteration") -> None:
        """Progress on stderr where the run shows it: `what` and its number, and
        chi-square; redrawn in place on a terminal, else a line once PIPED_PROGRESS_S
        seconds have passed since the last (or the run's start)."""
        if not self.progress:
            return
        text = f"  {what} {iteration:4d}   chi-square {chi2:14.6g}"
        if self._tty:  # padded: a longer line of the other kind may stand there
            sys.stderr.write(f"\r{text:<64}")
        else:
            now = time.monotonic()
            if now - self._said < PIPED_PROGRESS_S:
                return
            self._said = now
            sys.stderr.write(f"{text}   ({now - self._started:.0f} s)\n")
        sys.stderr.flush()

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
        if np.max(self.violations(g), initial=0.0) <= POLISH_CONSTRAINT_TOL:  # not NaN
            if chi2 < self._best_chi2:
                self.best, self._best_chi2 = np.asarray(arg[0]).ravel().copy(), chi2
            gain = STALL_GAIN if self._after_descent else max(STALL_GAIN,
                                                              STALL_SHARE * self.promised)
            if self._best_chi2 <= self._progress[0] - gain:
                self._progress = (self._best_chi2, self._done + self._k)
        patience = self._stall * (AFTER_DESCENT_STALLS if self._after_descent else 1) \
            if self._stall is not None else None
        if self._stalls and self.best is not None \
                and self._done + self._k - self._progress[1] >= patience:
            self.stalled = True
            return [1]
        if self.damping is not None:
            self.damping.observe(np.asarray(arg[0]).ravel())
        self.show(self._done + self._k, chi2)
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
#
# A run that goes on after a descent that did not finish it is stopped, as stalled, where
# its lowest nearly feasible chi-square then falls by less than STALL_GAIN in
# AFTER_DESCENT_STALLS times STALL_ITERATIONS iterations: a second descent would start
# where the first failed, and Ipopt left to its cap cycles.  (A share of the decrement
# found before the descent is no measure there: the late-events `drogue` fit, stopped
# at the first such rule, went on from its descent at iteration 58 with falls of 85,
# 33, 14 and 1.4 in chi-square (363,408 -> 363,275) and converged at iteration 135.)
# On the NDRT 2020 altimeter log (`problems/ndrt_2020.json`: the drogue opening at
# apogee, its start time anywhere in 17.0-18.5 s within 1 of chi-square) the run stalled
# at iteration 51, the descent failed (17 steps, a feasible chi-square of 385 against the
# run's nearly feasible 349), and Ipopt then repeated a cycle of three steps (chi-square
# 349.80 / 349.79 / 349.80, the barrier parameter held at 1.6e-4) to its 500th iteration:
# 75 s, where the shape restarts that converged took 8 s.
STALL_ITERATIONS = 20


AFTER_DESCENT_STALLS = 2


# Descents one solve may make.  A run that stalls again after a descent that did not
# finish it descends once more only where its lowest nearly feasible chi-square has
# fallen by STALL_GAIN since that descent ended: the 10-minute log of
# `benchmarks/long_log.py` stalled first at chi-square 2,689 (made feasible: 9,782), its
# descent ended at 2,656.68 with a decrement of 0.012 (the test's tolerance 0.01), and
# Ipopt went on to 2,648.24 before it stalled again, where the run was stopped as a
# failure and the shape restarts took 10 more minutes.
MAX_DESCENTS = 3


STALL_SHARE = 0.1


STALL_GAIN = 1.0


@dataclass
class _Run:
    """Ipopt's runs within one solve: the last run's solution and statistics, the
    iterations of all, where a parameter last acted outside its window (None: nowhere)
    and how the feasible descent after a stall ended (None: none was made)."""

    sol: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    iterations: int = 0
    left: np.ndarray | None = None
    descended: DescentEnd | None = None
    stalls: int = 0
    # The lowest nearly feasible chi-square known when the last descent ended (Ipopt's
    # best then, or the descent's end): a later stall below it by STALL_GAIN is elsewhere.
    after_descent_chi2: float = np.inf

    def may_descend(self, best_chi2: float) -> bool:
        """Whether a stall with `best_chi2` the lowest nearly feasible chi-square is
        finished by a descent: the first stall, or one after a descent that did not
        finish the run where the chi-square has since fallen by STALL_GAIN (from a point
        no better, a descent would start where one failed), MAX_DESCENTS in all."""
        return self.stalls < MAX_DESCENTS and best_chi2 <= self.after_descent_chi2 - STALL_GAIN


class Solver:
    """Ipopt's runs on one transcribed NLP, and when a run is done."""

    def __init__(self, nlp: Transcription, linearisations: Linearisations,
                 starts: StartingPoints) -> None:
        """Ipopt's options and the iteration monitor that carries the stopping rule, for the
        NLP `nlp` (its settings are the solver's); `linearisations` give the stopping
        rule's Gauss-Newton steps, `starts` the reduction's start and feasible points."""
        self.nlp = nlp
        self.settings = s = nlp.settings
        self._linearisations = linearisations
        self._starts = starts
        # Gauss-Newton converges linearly, so Ipopt's dual infeasibility plateaus near
        # 1e-4 (scaled) long after the estimate has stopped moving; accept a point where
        # the objective no longer changes (relative 1e-9, i.e. ~1e-5 in chi-square, over
        # 5 iterations; a change of 1 in chi-square is the statistical scale) and the
        # constraints hold to 1e-8.  `solve` reports which criterion ended the run.
        self.options = {
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
        # the solver keeps only a reference to its callbacks
        self._monitor = IterationMonitor(nlp.z.numel(), nlp.g.numel(), nlp.violations,
                                         self._stop_test, s.chi2_step_tol, nlp.damping,
                                         STALL_ITERATIONS if s.descent_steps > 0 else None)
        # Ipopt itself is made by the first solve (`solve`, on the pattern the windows
        # fitted at its start keep): an estimator that is only linearised (a score
        # test's) never needs it.
        self._solver: ca.Function | None = None
        self._warm = False

    @property
    def ipopt(self) -> ca.Function:
        """Ipopt on this NLP (the one the last solve used; made here where none was)."""
        if self._solver is None:
            self.make_solver()
        return self._solver

    def make_solver(self, barrier: float | None = None) -> None:
        """Ipopt on the NLP, its derivatives on the pattern `self.nlp.windows` keeps; with
        `barrier`, warm-started (the caller passes the multipliers) at that barrier
        parameter, the bounds not pushed."""
        own = self.nlp
        if self.settings.point_cache:
            self._functions = ipopt_functions(own.points, own.curvature(), own.small_rows,
                                              own.windows, self._monitor.window_check,
                                              own.damping, self._levenberg())
            nlp, derivatives = self._functions.nlp, self._functions.options
        else:
            nlp, derivatives = own.expressions
        self._warm = barrier is not None
        warm = {} if barrier is None else {
            "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": barrier,
            "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9}
        self._solver = ca.nlpsol("reconstruction", "ipopt", nlp, {
            **self.options, **warm, **derivatives, "iteration_callback": self._monitor})

    def _levenberg(self) -> tuple[np.ndarray, float] | None:
        """The Levenberg term's columns of z (the free parameters) and size, or None."""
        delta = self.settings.levenberg
        return None if not delta else (self.nlp.param_index, float(delta))

    def _jacobian_values(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The stored values of the residual and constraint Jacobians at `z`."""
        points = self.nlp.points
        return points.residual_jacobian(z)[1].data, points.constraints(z)[1].data

    def fit_windows(self, *points: np.ndarray, widen: bool = False,
                    barrier: float | None = None) -> None:
        """Fit the parameters' windows of action to their Jacobians' nonzeros at a point (or
        widen them over several), and rebuild the solver on the pattern they keep; with
        `barrier`, one that goes on from a run that ended at that barrier parameter."""
        if not self.nlp.windows.active:
            return
        if widen:
            self.nlp.windows.widen(*map(self._jacobian_values, points))
        else:
            self.nlp.windows.fit(self._jacobian_values(points[0]))
        self.make_solver(barrier)

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
        the descent learnt the curvature, `feasible_descent`).
        """
        lbz, ubz = self._solve_bounds(bounds)
        z0 = (self._starts.initial_point() if start is None
              else start.z if isinstance(start, Fit) else np.asarray(start, dtype=float))
        z0 = np.clip(z0, lbz, ubz)
        t0 = time.perf_counter()
        cap = min(max_iter or self.settings.max_iter, self.settings.max_iter)
        self.fit_windows(z0)
        # No solver yet, or an earlier solve's restart left its warm-started one behind.
        if self._solver is None or self._warm:
            self.make_solver()
        # A what-if's sensitivities need Ipopt's own multipliers at its own solution.
        run = self._runs(z0, (lbz, ubz), cap, progress, not bounds or not sensitivities)
        z, stats, multipliers = self._outcome(run, time.perf_counter() - t0, start)
        if not stats.success:
            raise SolverFailure(stats.status, stats.iterations, stats.worst_constraint,
                                2.0 * stats.objective, self._last_iterate(z, stats))
        fit = self.nlp.fit_at(z, stats)
        fit.multipliers = multipliers
        if bounds and sensitivities:
            fit.sensitivities = self._bound_sensitivities(z, multipliers, list(bounds))
        return fit

    def _solve_bounds(self, bounds: dict[str, tuple[float, float]] | None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """The scaled variables' bounds, with `bounds` (SI) replacing those of the free
        parameters it names."""
        lbz, ubz = self.nlp.lbz.copy(), self.nlp.ubz.copy()
        n_states = self.nlp.sizes[0]
        for name, (lo, hi) in (bounds or {}).items():
            i = self.nlp.free.index(name)
            lbz[n_states + i], ubz[n_states + i] = lo / self.nlp.pscale[i], hi / self.nlp.pscale[i]
        return lbz, ubz

    def _runs(self, z0: np.ndarray, box: tuple[np.ndarray, np.ndarray], cap: int,
              progress: bool, stall: bool) -> _Run:
        """Ipopt from `z0` within `box` until a run ends the solve: converged or stopped by
        the statistical test, finished by the feasible descent after a stall (`stall`:
        a stall may end a run), out of its `cap` iterations, or failed; a run whose
        parameters act outside their windows goes on with the windows widened."""
        run = _Run()
        multipliers: dict[str, ca.DM] = {}
        after_descent = False
        while True:
            self._monitor.reset(progress, box, cap - run.iterations, run.iterations, stall)
            if after_descent:
                self._monitor.count_progress_from(run.iterations)
                after_descent = False
            with interrupts.deferred():  # a signal stops Ipopt at its next iteration
                run.sol = self._solver(x0=z0, lbx=box[0], ubx=box[1], lbg=self.nlp.lbg,
                                       ubg=self.nlp.ubg, **multipliers)
            run.stats = self._solver.stats()
            run.iterations += int(run.stats["iter_count"])
            z0 = np.asarray(run.sol["x"]).ravel()
            multipliers = {"lam_x0": run.sol["lam_x"], "lam_g0": run.sol["lam_g"]}
            # No iteration record where Ipopt stopped at its first evaluation (a NaN there).
            mu = run.stats.get("iterations", {}).get("mu", [])
            barrier = float(mu[-1]) if len(mu) else None
            run.left = self._monitor.left_at
            if self._monitor.stalled:
                if not run.may_descend(self._monitor.best_chi2):
                    break
                run.stalls += 1
                run.descended = self._descend(z0, box, cap - run.iterations)
                run.iterations += run.descended.steps if run.descended is not None else 0
                if (run.descended is not None and run.descended.converged) \
                        or run.iterations >= cap:
                    break
                # Not finished that way: Ipopt goes on from its iterate, and is stopped as
                # stalled (a failure) where it makes no progress in STALL_ITERATIONS more.
                if run.descended is not None and run.descended.steps:
                    self._monitor.offer(run.descended.z, run.descended.chi2)
                run.after_descent_chi2 = self._monitor.best_chi2
                self.make_solver(barrier)
                after_descent = True
                continue
            if run.left is None and run.stats["success"] and self.nlp.windows.active \
                    and self.nlp.windows.outside_at(self._jacobian_values(z0)):
                # What Ipopt converged on must hold with every entry: a parameter that
                # acts outside its window at the end sends the run on.
                run.left = z0
            if run.left is None or self._monitor.capped or run.iterations >= cap:
                break
            # A parameter acts outside its window (a start time moved further than the
            # margin): widen the windows over both points and go on from the iterate,
            # with its multipliers and barrier parameter (from the default barrier and
            # least-squares multipliers, the first steps of the new run were regularised
            # and cut: on `drogue_full` 35 iterations in all against 30).
            self.fit_windows(run.left, z0, widen=True, barrier=barrier)
        self._monitor.finish()
        return run

    def _outcome(self, run: _Run, wall: float, start: Fit | np.ndarray | None
                 ) -> tuple[np.ndarray, SolverStats, np.ndarray]:
        """The point a solve ends at (Ipopt's, the statistical test's own step's end, or the
        descent's), its statistics, and Ipopt's constraint multipliers."""
        sol = run.sol
        z = np.asarray(sol["x"]).ravel()
        multipliers = np.asarray(sol["lam_g"]).ravel()
        status, success = self._run_status(run.stats, run.left is not None)
        decrement = self._monitor.decrement if self._monitor.stopped else None
        own_point = self._monitor.stopped and self._monitor.point is not None
        if own_point:
            # The statistical test ended the run at its own Gauss-Newton step's end.
            z = self._monitor.point
        descended = run.descended
        if descended is not None and descended.converged:
            z, own_point, decrement = descended.z, True, descended.decrement
            status, success = DESCENT_CONVERGED, True
        if own_point or not success:
            # Evaluated here: Ipopt's values describe its last iterate, and after a failure
            # can be placeholders (zeros after an invalid number).
            r = self.nlp.points.residual_value(z)
            objective = 0.5 * float(r @ r)
            g = self.nlp.points.constraint_value(z)
        else:
            g, objective = np.asarray(sol["g"]).ravel(), float(sol["f"])
        worst = worst_violation(self.nlp.violations(g))
        stats = SolverStats(status, success, run.iterations, wall, objective, worst, decrement,
                            FROM_REDUCTION if start is None else
                            "a fit" if isinstance(start, Fit) else "a given point")
        return z, stats, multipliers

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
        if self.settings.descent_steps <= 0 or not tol or self.nlp.has_inequalities:
            return None
        points = [self._starts.feasible_point(x) for x in (z, self._monitor.best) if x is not None]
        points = [p for p in points if p is not None]
        if not points:
            return None
        start = min(points, key=lambda p: p[1])
        idx = self.nlp.param_index
        lower, upper = bounds
        problem = DescentProblem(self._linearisations.linearise, self._starts.feasible_point,
                                 self.nlp.points.residual_value, idx, lower[idx], upper[idx])
        return descend(*start, problem, tol, min(self.settings.descent_steps, left),
                       step_taken=lambda k, chi2: self._monitor.show(
                           k, chi2, "feasible Gauss-Newton step"))

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
            return self.nlp.fit_at(z, stats)
        except (RuntimeError, ValueError):
            return None

    def _bound_sensitivities(self, z: np.ndarray, lam_g: np.ndarray,
                             names: list[str]) -> dict[str, float]:
        """d(chi^2)/d(value) of each bounded parameter at a solution: twice the gradient of
        the Lagrangian of the other constraints in that parameter (SI units)."""
        r, jac = self.nlp.points.residual_jacobian(z)
        _, jac_g = self.nlp.points.constraints(z)
        grad = jac.T @ r + jac_g.T @ lam_g
        n_states = self.nlp.sizes[0]
        return {n: float(2.0 * grad[n_states + self.nlp.free.index(n)]
                         / self.nlp.pscale[self.nlp.free.index(n)]) for n in names}

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

        Where the step carries a parameter through a bound it lies so near that less than
        the tolerance is to be had before it (`gauss_newton.bound_reached`), the test is
        made from the iterate with that parameter on its bound, where it is held: the
        point the run ends at then has it there, as the claim's bound tests expect.
        """
        tol = self.settings.chi2_step_tol or 0.0
        point = self._stop_linearisation(z)
        if point is None:
            return None
        lin, may_polish = point
        gn = gauss_newton(lin)
        reached = bound_reached(lin, gn, *self._monitor.bounds, tol, self.nlp.param_index)
        if reached is not None:  # the test is made on that face, from the bound
            z = z.copy()
            z[reached[0]] = reached[1]
            point = self._stop_linearisation(z)
            if point is None:
                return None
            lin, may_polish = point
            gn = gauss_newton(lin)
        violation = lin.violation
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

    def _stop_linearisation(self, z: np.ndarray) -> tuple[Linearisation, bool] | None:
        """The problem linearised at `z` and whether finishing steps may start there; None
        where `z` can neither end the run nor be finished (its scaled constraints beyond
        POLISH_CONSTRAINT_TOL), which is told before any Gauss-Newton solve."""
        lin = self._linearisations.linearise(z)
        # An inequality (a what-if limit) inactive at z might be crossed by the finishing
        # step unseen: the linearisation holds only the active ones.
        may_polish = lin.violation <= POLISH_CONSTRAINT_TOL and not self.nlp.has_inequalities
        if lin.violation > STOP_CONSTRAINT_TOL and not may_polish:
            return None
        return lin, may_polish

    def _finishing_steps(self, lin: Linearisation, gn: GaussNewtonStep, tol: float
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
    def _feasible(candidate: tuple[Linearisation, GaussNewtonStep], tol: float) -> bool:
        """Whether a candidate's point meets STOP_CONSTRAINT_TOL and closing its remaining
        gaps is worth less than `tol` in chi-square."""
        lin, gn = candidate
        return lin.violation <= STOP_CONSTRAINT_TOL and abs(gn.restoration) <= tol

    def _candidate(self, z: np.ndarray, lower: np.ndarray, upper: np.ndarray, limit: float
                   ) -> tuple[Linearisation, GaussNewtonStep] | None:
        """The linearisation and Gauss-Newton step at a point where the run might stop, if it
        lies within the bounds and its scaled constraints within `limit` (judged on their
        values first: 3 ms on `drogue`, where a linearisation takes 70)."""
        if np.any(z < lower) or np.any(z > upper) \
                or not self.nlp.value_violation(z) <= limit:  # NaN too
            return None
        lin = self._linearisations.linearise(z)
        return lin, gauss_newton(lin)

    def _measured_decrement(self, lin: Linearisation, gn: GaussNewtonStep) -> float:
        """The chi-square decrease still to be had along `gn` from `lin.z`, its curvature
        measured (`uncertainty.measured_decrement`)."""
        return measured_decrement(self.nlp.points.residual_value, lin, gn, self._monitor.bounds)
