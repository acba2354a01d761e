"""The effect plug-in interface.

An effect is one piece of physics or one sensor model.  It declares its
parameters, any states and captured quantities it adds, and contributes to the
model in two passes over a shared symbolic `ModelContext`:

1. `forces`: aerodynamic and body forces on the vehicle (N, 3-vectors in
   east-north-up), masses, derivatives of its own states, and named
   quantities others may use (``cds[drogue1]``, ``drag[drogue1]`` ...);
2. `observations`: sensor predictions and quantities that need the system's
   specific force, which the model computes between the passes.

Everything is written once in CasADi symbols, so the estimator, the simulator
and the sensitivities all use the same code.  Adding a physical effect means
writing one subclass in one file and naming it in the problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import casadi as ca
import numpy as np

from cpas_ocp.physics.parameters import Parameter

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext


@dataclass(frozen=True)
class State:
    """A differential state: name, size, SI unit, typical magnitude (for scaling).

    `initial` is the value of every component at the start of a simulation
    unless the problem's initial state names it.  A `pinned` state is known
    at the start of the phase: the estimator holds its first node at
    `initial` instead of estimating it.
    """

    name: str
    size: int
    unit: str
    scale: float
    initial: float = 0.0
    pinned: bool = False


@dataclass(frozen=True)
class Capture:
    """The value of a model quantity at the instant given by a time parameter.

    Example: a stage's start airspeed V_i is ``airspeed`` captured at
    ``t_start[drogue1,stage2]``.  The estimator makes it a decision variable
    tied to the trajectory; the simulator records it when the event happens.
    With `at_time` set, the instant is that fixed time (s) instead, and
    `time_parameter` is empty (an observed event time, see `EventTiming`).
    `lower` bounds the captured value in the estimation problem.
    """

    name: str
    time_parameter: str
    quantity: str
    unit: str
    at_time: float | None = None
    lower: float = -math.inf


@dataclass(frozen=True)
class EventTiming:
    """How the model predicts the time of an observed event.

    Either `time` names a scalar quantity that is the predicted time itself
    (s, a function of parameters and captured values only: a Pilot's Main bag
    lift at t_i + t_f), or `crossing` names a scalar quantity of the state
    whose first rise through zero is the event (the Main bag strips when the
    deployed length reaches the line length).  For a crossing the model
    captures the quantity g and its rate g' at the observed time t_obs and
    predicts t_obs - g/g' (the first-order time of the crossing).  Where the
    test has no such event, the timing is not used.
    """

    event: str
    parachute: str
    stage: str | None = None
    time: str | None = None
    crossing: str | None = None

    def __post_init__(self) -> None:
        if (self.time is None) == (self.crossing is None):
            raise ValueError(f"event timing {self.event}: give exactly one of time, crossing")


@dataclass(frozen=True)
class Refinement:
    """A generalisation of an effect: the same physics with a structural constant freed as a
    parameter (a growth exponent, a start time), for `discover` to test against the
    effect as it is.

    `effect` is the refined effect (the same `name`, so it takes the original's place in
    a model); `change` says in a few words what was freed; `null` gives the freed
    parameters' values at which the refined effect is the original (the null of the
    likelihood ratio, inside their bounds: a two-sided test on len(null) degrees of
    freedom); `starts` other values of them to refit from besides the null (a freed
    constant's chi-square can have several minima: the fit being refined has bent its
    other parameters to the constant's fixed value)."""

    effect: Effect
    change: str
    null: dict[str, float]
    starts: tuple[dict[str, float], ...] = ()


@dataclass(frozen=True)
class Constraint:
    """A constraint lower <= expr <= upper declared by an effect; expr is a function of
    the parameters and the captured values (``ctx.p``, ``ctx.c``)."""

    label: str
    expr: ca.SX
    lower: float
    upper: float


class Effect:
    """Base class: an effect contributes nothing until it overrides a hook.

    `replaces` names the effect this one stands in for when it is added to a
    model that has that one (an elastic riser replaces the rigid riser).
    `continuation`: the effect changes the dynamics so much that a fit from
    the offline reduction rarely converges with it; the model is then first
    fitted without it (with the effect it replaces, if any), and the effect
    brought in from that fit (`cpas_ocp.inference.continuation`).
    """

    name: str = "effect"
    replaces: ClassVar[str | None] = None
    continuation: ClassVar[bool] = False

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return []

    def states(self, test: FlightTest) -> list[State]:
        return []

    def captures(self, test: FlightTest) -> list[Capture]:
        return []

    def event_timings(self, test: FlightTest) -> list[EventTiming]:
        """Observable events this effect predicts (their quantities it writes in `forces`)."""
        return []

    def state_guess(self, test: FlightTest, t: np.ndarray,
                    values: dict[str, float]) -> dict[str, np.ndarray]:
        """Initial guess of this effect's states on the shooting grid `t` (s), from the data.

        `values` holds the initial parameter values.  States left out start at zero.
        """
        return {}

    def forces(self, ctx: ModelContext) -> None:
        """First pass: forces, masses, state derivatives, quantities."""

    def observations(self, ctx: ModelContext) -> None:
        """Second pass: sensor predictions (after the specific force is known)."""

    def constraints(self, ctx: ModelContext) -> list[Constraint]:
        return []

    def penalties(self, ctx: ModelContext) -> dict[str, tuple[np.ndarray, ca.SX]]:
        """Pseudo-observations: by channel, their times (s) and a vector of residuals in units
        of their sigma, functions of the parameters only (``ctx.p``).  They join
        chi-square as a sensor named after the effect: a stated prior on the effect's
        parameters, such as a stochastic process's innovations (`wind_process`)."""
        return {}

    def process_priors(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """The stochastic process parameters among this effect's, each with its time (s)
        and the marginal standard deviation of its stated prior (the parameter's unit):
        a fit that puts one far beyond that sigma is not a result (`result_claim`).
        Parameters not named have no such prior."""
        return {}

    def plausible(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """The range (SI) within which each named parameter's estimate is physically
        plausible, narrower than its bounds (which only keep the solver in the model's
        domain).  An estimate outside marks the effect a stand-in for something it does
        not describe (a GPS lag of -0.06 s: the receiver would report before the event).
        Parameters not named have no such range."""
        return {}

    def refinements(self, test: FlightTest) -> list[Refinement]:
        """Generalisations of this effect that free one of its structural constants
        (`Refinement`); none by default.  A refined effect has none of its own."""
        return []

    def null_values(self, test: FlightTest) -> dict[str, float] | None:
        """Values of this effect's parameters at which it changes no prediction: the model
        without the effect is the model with it at these values (the null hypothesis of
        its score test, `score_test`).  Parameters not named are held at their defaults.

        None: the model without the effect is not nested in the model with it at any
        parameter value; it can only be compared by refitting both.
        """
        return None
