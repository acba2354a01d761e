"""What a solve returns: the fit (trajectory, parameters, captured values, residuals per
sensor channel), the solver's statistics, and the settings the estimator was built with.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: the command line's parser reads this module's limits
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model import Model


@dataclass
class Settings:
    """Transcription and solver settings.

    The transcription (`transcription.Transcription`) reads grid_step, nodes,
    substeps, compile, free, fixed, guess, limits, point_cache and
    window_margin; the solver (`solve.Solver`) reads max_iter, tol,
    chi2_step_tol, verbose, watchdog_trigger, levenberg and descent_steps.

    grid_step (s): a uniform shooting interval, forced (None: a grid chosen
    from the dynamics, `shooting_grid`, on the lattice of the finest sampling
    interval of the test's sensors, `default_grid_step`);
    nodes: the grid's nodes (s) as given; an estimator records its grid here,
    so that a model built from its settings (a nested or extended fit, a
    profile) shares it;
    interval_steps: the RK4 sub-steps of each interval of `nodes` (an estimator
    records its grid's here; None: from the intervals' lengths,
    `shooting_grid.substeps_of`);
    substeps: RK4 steps per sub-step (a multiplier on every interval's);
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
    point_cache: give Ipopt functions that share one native evaluation of the
    residuals, constraints and their Jacobians per point (`nlp_functions`;
    False: CasADi expressions, each evaluating what it needs in turn, the
    independent reference the suite checks these functions against,
    `tests/estimation/test_nlp_functions.py`).
    levenberg: a Levenberg term on the free parameters' diagonal of the Hessian
    Ipopt is given (per scaled unit squared; `nlp_functions.ipopt_functions`,
    needs point_cache; None: the earlier path).  It bounds the steps along
    parameters the data hardly determine at the iterate, such as a stiff
    elastic riser's damping ratio, whose Gauss-Newton steps were cut to
    1/128-1/256 and sent the watchdog's trial steps to chi-square 1e5-1e8.
    window_margin (s): Ipopt gets each parameter's Jacobian entries only within
    its window of action at the start, widened by this much on each side
    (`action_windows`; a solve restarts with wider windows when a parameter
    acts outside them); None gives Ipopt every structural entry (the reference
    the suite checks the windows against; needs point_cache).
    descent_steps: a run whose chi-square has stopped falling (STALL_ITERATIONS)
    is stopped, and at most this many Gauss-Newton steps through feasible
    points from its iterate may finish the fit at the statistical test
    (`feasible_descent`); they count as iterations.  Where they do not, Ipopt
    goes on from its iterate, and a run that stalls again is stopped as stalled
    (`solve.STALL_ITERATIONS`).  A finish, not a second engine: on the
    misspecified refits it served, 8-11 steps ended the run, and a descent
    that needed 29 had ended in a worse minimum than Ipopt's.  0: Ipopt runs
    on to its limit (the earlier path, for benchmarks).
    local_series: a model whose series of knots in time (a wind process) are read a
    few knots per shooting interval gives the estimator's Jacobians only those
    knots' columns (`series_slots`; False: every knot's column in every row,
    the reference the suite checks the local one against).

    The statistical test may finish a nearly feasible run with Gauss-Newton
    steps of its own (`Solver._stop_test`); Ipopt's Gauss-Newton Hessian is
    Levenberg-Marquardt damped where its steps fail to deliver
    (`nlp_functions.MarquardtDamping`, with point_cache); and the descent
    after a stall learns what the Gauss-Newton model leaves out, the curvature
    of chi-square along the feasible curve and the residuals' own
    (`feasible_descent`, `structured_secant`).  The paths before these
    (Settings' `polish`, `damping` and `descent_curvature` switches) are kept
    by revision f73876d, which the benchmarks that compare with them run
    (`benchmarks/revisions.py`).
    """

    grid_step: float | None = None
    nodes: tuple[float, ...] | None = None
    interval_steps: tuple[int, ...] | None = None
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
    point_cache: bool = True
    levenberg: float | None = 1.0
    window_margin: float | None = 0.5
    descent_steps: int = 30
    local_series: bool = True


MIN_GRID_STEP_S = 0.001


HESSIANS = ("gauss-newton", "exact")  # curvatures a covariance may invert


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
    stalled runs' descent learns the curvature (`feasible_descent`)
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
    def normalised(self) -> np.ndarray:
        return (self.measured - self.model) / self.sigma


# Sensor name under which observed event times appear among the residuals.
EVENTS = "events"


# Sensor name under which the model's priors on free parameters appear (`ModelSpec.priors`).
PRIORS = "priors"


# Residuals that are not a sensor's time series.
PSEUDO_SENSORS = (EVENTS, PRIORS)


# `SolverStats.start` of a solve from the offline reduction's initial point.
FROM_REDUCTION = "the offline reduction"


@dataclass
class SolverStats:
    status: str
    success: bool
    iterations: int
    wall_s: float
    objective: float
    worst_constraint: str = ""
    chi2_decrement: float | None = None
    start: str = FROM_REDUCTION  # where the solve started from


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
        return float(sum(np.sum(r.normalised**2) for r in self.residuals))

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

    @property
    def sensors(self) -> list[str]:
        """The sensors with residuals in the fit, in order, the pseudo-sensors left out."""
        return list(dict.fromkeys(r.sensor for r in self.residuals
                                  if r.sensor not in self.pseudo_sensors))

    def quantities(self) -> dict[str, np.ndarray]:
        """Every scalar model quantity (cds[P], tension[P], dynamic_pressure, ...) on the grid."""
        return self.model.quantities_along(self.t, self.x, self.parameters, self.captures)


# Largest scaled constraint violation at which that test may stop a run.
STOP_CONSTRAINT_TOL = 1e-6


# Largest scaled violation from which the test tries one Gauss-Newton step of its own to
# finish the run (`Solver._stop_test`): Ipopt's Gauss-Newton iterations close the last
# shooting gaps only as fast as the steps shrink, linearly.
POLISH_CONSTRAINT_TOL = 1e-3
