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

The estimator is composed of four parts, each owning its state: the NLP
(`transcription.Transcription`), its linearisations with the covariance and
Gauss-Newton quantities (`linearisation.Linearisations`), the points a solve starts
from and the feasible points integrations give (`starting_points.StartingPoints`),
and the Ipopt runs with the statistical stopping rule (`solve.Solver`); `fit` holds
what a solve returns.  `Estimator` builds the four and answers for them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np

from cpas_ocp import interrupts
from cpas_ocp.estimation.fit import (
    EVENTS,
    MAX_LATTICE_STEP_S,
    MIN_GRID_STEP_S,
    PRIORS,
    PSEUDO_SENSORS,
    Fit,
    SensorResidual,
    Settings,
    SolverStats,
    default_grid_step,
)
from cpas_ocp.estimation.linearisation import Linearisations
from cpas_ocp.estimation.solve import (
    DESCENT_CONVERGED,
    DIVERGED_FACTOR,
    POLISH_CONSTRAINT_TOL,
    STALL_ITERATIONS,
    STALL_SHARE,
    STALLED,
    STATISTICALLY_CONVERGED,
    STOP_CONSTRAINT_TOL,
    Solver,
)
from cpas_ocp.estimation.starting_points import StartingPoints
from cpas_ocp.estimation.transcription import Transcription
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model

__all__ = ["DESCENT_CONVERGED", "DIVERGED_FACTOR", "EVENTS", "MAX_LATTICE_STEP_S",
           "MIN_GRID_STEP_S", "POLISH_CONSTRAINT_TOL", "PRIORS", "PSEUDO_SENSORS",
           "STALLED", "STALL_ITERATIONS", "STALL_SHARE", "STATISTICALLY_CONVERGED",
           "STOP_CONSTRAINT_TOL", "Estimator", "Fit", "SensorResidual", "Settings", "SolverStats",
           "default_grid_step", "reconstruct"]


class Estimator:
    """The NLP of one test phase, built once; `solve` may then be called repeatedly.

    Its parts: `transcription` (the NLP), `linearisations` (covariance and
    Gauss-Newton quantities at a point), `starts` (starting and feasible points)
    and `solver` (Ipopt and its stopping rule).  The methods below are theirs.
    """

    def __init__(self, test: FlightTest, effects: Sequence[Effect] | ModelSpec | None = None,
                 settings: Settings | None = None) -> None:
        """`effects`: an effect list, a `ModelSpec`, or None for the model the manifest declares.

        `settings.free` and `settings.fixed` override the spec's choice.

        Built with signals deferred (`interrupts.deferred`): CasADi's wrappers clear
        a Python exception raised inside them while they match argument types, so an
        `Interrupted` raised there by a signal's handler would be lost and the
        command would run on; deferred, it is raised once the build is done.
        """
        with interrupts.deferred():
            self.transcription = Transcription(test, effects, settings)
            self.linearisations = Linearisations(self.transcription)
            self.starts = StartingPoints(self.transcription, self.linearisations)
            self.solver = Solver(self.transcription, self.linearisations, self.starts)

    # ---------------------------------------------------------------- what was transcribed
    @property
    def test(self) -> FlightTest:
        """The test phase the NLP reconstructs."""
        return self.transcription.test

    @property
    def settings(self) -> Settings:
        """The settings, with the shooting grid's nodes the transcription chose."""
        return self.transcription.settings

    @property
    def spec(self) -> ModelSpec:
        """The model specification the NLP was built from."""
        return self.transcription.spec

    @property
    def model(self) -> Model:
        """The vehicle's model."""
        return self.transcription.model

    @property
    def free(self) -> list[str]:
        """The free parameters' names, in the decision vector's order."""
        return self.transcription.free

    @property
    def t(self) -> np.ndarray:
        """The shooting nodes (s)."""
        return self.transcription.t

    @property
    def guess(self) -> dict[str, float]:
        """Every parameter's first guess (SI), the reduction's or given."""
        return self.transcription.guess

    @property
    def values(self) -> dict[str, float]:
        """The first guesses with the fixed values over them (SI)."""
        return self.transcription.values

    @property
    def unfitted(self) -> list[str]:
        """Sensors of the test that no effect of the model predicts."""
        return self.transcription.unfitted

    @property
    def pscale(self) -> np.ndarray:
        """The free parameters' scales (SI per unit of the decision vector)."""
        return self.transcription.pscale

    def size_text(self) -> str:
        """One line describing the NLP's size."""
        return self.transcription.size_text()

    def with_value(self, z: np.ndarray, name: str, value: float) -> np.ndarray:
        """A copy of the decision vector `z` with the free parameter `name` at `value` (SI)."""
        return self.transcription.with_value(z, name, value)

    def free_values(self, z: np.ndarray) -> dict[str, float]:
        """The free parameters at the decision vector `z` (SI)."""
        return self.transcription.free_values(z)

    def fit_at(self, z: np.ndarray, stats: SolverStats) -> Fit:
        """The Fit at the decision vector `z`, with a solve's `stats`."""
        return self.transcription.fit_at(z, stats)

    # ---------------------------------------------------------------- solving
    def solve(self, progress: bool = False, start: Fit | np.ndarray | None = None,
              bounds: dict[str, tuple[float, float]] | None = None,
              max_iter: int | None = None, sensitivities: bool = True) -> Fit:
        """Solve the NLP and return the Fit; raise SolverFailure if it fails (`Solver.solve`)."""
        return self.solver.solve(progress, start, bounds, max_iter, sensitivities)

    @property
    def ipopt(self) -> ca.Function:
        """Ipopt on this NLP (`Solver.ipopt`)."""
        return self.solver.ipopt

    @property
    def best_iterate(self) -> np.ndarray | None:
        """The last solve's lowest nearly feasible iterate (`Solver.best_iterate`)."""
        return self.solver.best_iterate

    # ---------------------------------------------------------------- points
    def initial_point(self) -> np.ndarray:
        """The start from the kinematic track and the reduction (`StartingPoints`)."""
        return self.starts.initial_point()

    def point_from(self, fit: Fit, values: dict[str, float] | None = None) -> np.ndarray:
        """This NLP's decision vector at another fit (`StartingPoints.point_from`)."""
        return self.starts.point_from(fit, values)

    def decision_vector(self, states: np.ndarray, values: dict[str, float],
                        captures: dict[str, float]) -> np.ndarray:
        """The scaled decision vector of SI states, values and captures."""
        return self.starts.decision_vector(states, values, captures)

    def extension_start(self, fit: Fit, values: dict[str, float] | None = None
                        ) -> tuple[np.ndarray, tuple[float, float]]:
        """The start at a fit of a model this one extends (`StartingPoints.extension_start`)."""
        return self.starts.extension_start(fit, values)

    def swept(self, z: np.ndarray, states: Sequence[str]) -> np.ndarray:
        """`z` with the named states integrated through the grid (`StartingPoints.swept`)."""
        return self.starts.swept(z, states)

    def feasible_point(self, z: np.ndarray) -> tuple[np.ndarray, float] | None:
        """A feasible point near `z` and its chi-square (`StartingPoints.feasible_point`)."""
        return self.starts.feasible_point(z)

    # ---------------------------------------------------------------- linearisations
    def covariance(self, fit: Fit, scale_by_residual: bool = False,
                   hessian: str = "gauss-newton") -> Covariance:
        """Covariance of the free parameters at `fit` (`Linearisations.covariance`)."""
        return self.linearisations.covariance(fit, scale_by_residual, hessian)

    def covariance_at(self, z: np.ndarray, scale_by_residual: bool = False,
                      hessian_product: Callable[[np.ndarray], np.ndarray] | None = None
                      ) -> Covariance:
        """Covariance of the free parameters at a decision vector (`Linearisations`)."""
        return self.linearisations.covariance_at(z, scale_by_residual, hessian_product)

    def gauss_newton_estimate(self, z: np.ndarray, release: Sequence[str] = ()
                              ) -> tuple[dict[str, float], Covariance]:
        """The free parameters after one Gauss-Newton step from `z`, and their covariance."""
        return self.linearisations.gauss_newton_estimate(z, release)

    def gauss_newton_point(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """One full Gauss-Newton step's end from `z`, clipped, and chi-square at `z`."""
        return self.linearisations.gauss_newton_point(z)

    def information_log_det(self, fit: Fit) -> float:
        """log det of the Gauss-Newton information at `fit` (`Linearisations`)."""
        return self.linearisations.information_log_det(fit)

    def evaluate(self, z: np.ndarray) -> tuple[float, float]:
        """Chi-square at `z` and its largest scaled constraint violation."""
        return self.linearisations.evaluate(z)


def reconstruct(test: FlightTest, effects: Sequence[Effect] | ModelSpec | None = None,
                settings: Settings | None = None) -> Fit:
    """Reconstruct one test phase: build the NLP, solve it, return the Fit."""
    return Estimator(test, effects, settings).solve()
