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

The estimator is built in three parts: `transcription` (the NLP), `solve` (Ipopt and
the stopping rule) and `linearisation` (covariance and Gauss-Newton quantities);
`fit` holds what a solve returns.
"""

from __future__ import annotations

from collections.abc import Sequence

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
from cpas_ocp.estimation.linearisation import Linearising
from cpas_ocp.estimation.solve import (
    DESCENT_CONVERGED,
    DIVERGED_FACTOR,
    POLISH_CONSTRAINT_TOL,
    STALL_ITERATIONS,
    STALL_SHARE,
    STALLED,
    STATISTICALLY_CONVERGED,
    STOP_CONSTRAINT_TOL,
    Solving,
    _Monitor,
)
from cpas_ocp.estimation.transcription import NlpTranscription
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.flight_test import FlightTest

__all__ = ["DESCENT_CONVERGED", "DIVERGED_FACTOR", "EVENTS", "MAX_LATTICE_STEP_S",
           "MIN_GRID_STEP_S", "POLISH_CONSTRAINT_TOL", "PRIORS", "PSEUDO_SENSORS",
           "STALLED", "STALL_ITERATIONS", "STALL_SHARE", "STATISTICALLY_CONVERGED",
           "STOP_CONSTRAINT_TOL", "Estimator", "Fit", "SensorResidual", "Settings", "SolverStats",
           "_Monitor", "default_grid_step", "reconstruct"]


class Estimator(NlpTranscription, Solving, Linearising):
    """Builds the NLP of one test phase once; `solve` may then be called repeatedly.

    Three parts, one file each: `NlpTranscription` builds the NLP (`transcription`),
    `Solving` runs Ipopt on it and decides when a run is done (`solve`), and
    `Linearising` gives the covariance and the Gauss-Newton quantities at a point
    (`linearisation`).
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
            super().__init__(test, effects, settings)
            self._setup_solver()


def reconstruct(test: FlightTest, effects: Sequence[Effect] | ModelSpec | None = None,
                settings: Settings | None = None) -> Fit:
    """Reconstruct one test phase: build the NLP, solve it, return the Fit."""
    return Estimator(test, effects, settings).solve()
