"""Air motion along the flight as a Gauss-Markov process, estimated with the trajectory.

Real air moves: gusts, thermals and the shear of a boundary layer change the
airspeed a canopy sees by metres per second over seconds, and a model that
knows only the static atmosphere explains them with every parameter it has.
This effect adds the air's velocity u(t) (m/s, in the components named by
`components`: east, north, up) to the atmosphere's wind profile.  Each
component is piecewise linear in time between knots t_k = t_start + k D
(D = `knot_s`, s), whose values ``wind_up[k]``, ``wind_east[k]``,
``wind_north[k]`` (m/s) are free parameters: the air-relative velocity is

    v_air = v - u_atm(h) - u(t),

and every drag, dynamic pressure and captured airspeed sees it.

The knots have a stated prior: each component is a first-order Gauss-Markov
(Ornstein-Uhlenbeck) process, du = -u/tau dt + s sqrt(2/tau) dW, stationary
standard deviation s (`sigma_horizontal`, `sigma_vertical`, m/s) and
correlation time tau (`tau_s`, s).  Sampled at the knots,

    u_0 ~ N(0, s^2),   u_{k+1} = phi u_k + e_k,  phi = exp(-D/tau),  e_k ~ N(0, s^2 (1 - phi^2)),

so the residuals r_0 = u_0 / s and r_{k+1} = (u_{k+1} - phi u_k) / (s sqrt(1 - phi^2))
are standard normal under the prior.  They join chi-square as the
pseudo-sensor ``wind_process`` (`Effect.penalties`): the fit is then the
maximum a posteriori estimate of the wind together with every parameter and
start time (a smoother), and the wind cannot absorb more than its prior
allows.  s and tau are given, not estimated (defaults: 1 m/s horizontal,
0.5 m/s vertical, 5 s, for a calm to light boundary layer); the score test
at u = 0 (`null_values`) asks whether the data want any air motion at all.

*The mean vertical motion.*  A Gauss-Markov process lets its time average
over a phase of T s wander by about s sqrt(2 tau / T) (0.45 m/s for s = 1
m/s, tau = 20 s, T = 200 s), and a fit whose data outweigh that prior (a
sensor whose correlated noise is counted as white, or a reading no drag can
make) parks a column of sinking or rising air of metres per second under the
vehicle and moves the drag area to keep the descent rate.  The atmosphere
does not do that.  Averaged over a descent of minutes, vertical air motion
is near zero: large-scale subsidence and ascent are centimetres per second
(continuity: horizontal divergence of 1e-5 1/s over a few kilometres), and
mesoscale convergence lines and gravity waves tenths of a metre per second;
thermals of metres per second are local (hundreds of metres across) and
brief to a vehicle falling through them, and they are fed by compensating
sinking air around them, so the mean over the path stays small.  Only the
lee waves downwind of a mountain ridge hold metres per second for minutes.
`sigma_mean_vertical` (m/s; None: no such statement) says this separately
from the gusts: the time average of the vertical component over the phase,
u_mean = (1/T) integral u dt (a linear function of the knots,
`mean_weights`), joins chi-square as one more standardised residual
u_mean / sigma_mean_vertical (channel ``wind_up_mean``).  The prior is then
the Gauss-Markov process conditioned on a zero mean known to that sigma: the
gusts keep their sigma and correlation time, and only the long average is
held (to 1/sqrt(1/sigma_mean^2 + T/(2 s^2 tau)); 0.2 m/s for 0.25 m/s with
the numbers above).  The rocket default (`vertical_thermals`) holds it at
0.25 m/s; a site in the lee of a ridge should say more.

The knots are as many parameters as the phase has knot intervals per
component: D = 1 s on a 20 s phase adds 21 per component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

COMPONENTS = ("east", "north", "up")
# Quantities of the air-relative flow the model's environment writes; this effect rewrites
# them before any drag is formed from them.
FLOW = ("airspeed", "dynamic_pressure", "drag_direction")
# Bound of a knot value (m/s): far beyond any gust a parachute test flies in; a bound, not a
# prior (the prior is the process).
MAX_WIND_M_S = 30.0
PENALTY = "wind_process"
# Sigma of the vertical air motion's mean over a rocket's descent (m/s): subsidence is
# centimetres per second, mesoscale lifting and gravity waves tenths (module docstring).
VERTICAL_MEAN_SIGMA_M_S = 0.25


@dataclass(frozen=True)
class WindProcess(Effect):
    """Air velocity u(t) as knots of a Gauss-Markov process (see the module docstring).
    List it before the effects that form drag (`canopy_inflation`, `forebody_drag`)."""

    components: tuple[str, ...] = COMPONENTS
    knot_s: float = 1.0
    tau_s: float = 5.0
    sigma_horizontal: float = 1.0
    sigma_vertical: float = 0.5
    sigma_mean_vertical: float | None = None
    name: str = "wind_process"

    def __post_init__(self) -> None:
        components = tuple(self.components)
        object.__setattr__(self, "components", components)
        if not components or any(c not in COMPONENTS for c in components) \
                or len(set(components)) != len(components):
            raise ValueError(f"components: some of {', '.join(COMPONENTS)}, each once; "
                             f"got {list(components)}")
        for label, value in (("knot_s", self.knot_s), ("tau_s", self.tau_s),
                             ("sigma_horizontal", self.sigma_horizontal),
                             ("sigma_vertical", self.sigma_vertical)):
            if isinstance(value, bool) or not (isinstance(value, int | float)
                                               and math.isfinite(value) and value > 0):
                raise ValueError(f"{label} must be a positive number; got {value!r}")
        held = self.sigma_mean_vertical
        if held is not None and (isinstance(held, bool) or not (
                isinstance(held, int | float) and math.isfinite(held) and held > 0)):
            raise ValueError(f"sigma_mean_vertical must be a positive number or null; got "
                             f"{held!r}")
        if held is not None and "up" not in components:
            raise ValueError("sigma_mean_vertical holds the vertical component's mean: "
                             f"components must include up; got {list(components)}")

    @classmethod
    def vertical_thermals(cls) -> WindProcess:
        """The vertical air motion of a rocket's descent through an afternoon boundary
        layer: thermals of about 1 m/s correlated over tens of seconds (tau 20 s), knots
        every 4 s, their mean over the descent held at 0.25 m/s (`sigma_mean_vertical`,
        module docstring).  The altimeter and a GPS altitude see only the vertical
        component."""
        return cls(components=("up",), knot_s=4.0, tau_s=20.0, sigma_vertical=1.0,
                   sigma_mean_vertical=VERTICAL_MEAN_SIGMA_M_S)

    def knot_times(self, test: FlightTest) -> np.ndarray:
        """The knot times t_k (s): every `knot_s` from the phase's start, the last at or past
        its end."""
        n = math.ceil((test.t_end - test.t_start) / self.knot_s - 1e-9)
        return test.t_start + self.knot_s * np.arange(n + 1)

    def mean_weights(self, test: FlightTest, component: str, t0: float, t1: float
                     ) -> dict[str, float]:
        """The mean of u_component over [t0, t1] (s) as weights of its knots: the hat
        functions averaged over the window (a linear function of the knots)."""
        knots = self.knot_times(test)
        t = np.clip(np.linspace(t0, t1, 401), knots[0], knots[-1])
        hats = np.maximum(0.0, 1.0 - np.abs(t[:, None] - knots[None, :]) / self.knot_s)
        weights = hats.mean(axis=0)
        return {param_name(f"wind_{component}", str(k)): float(w)
                for k, w in enumerate(weights) if w > 0.0}

    def knot_weights(self, test: FlightTest, t0: float, t1: float) -> np.ndarray:
        """`mean_weights` of the vertical component as a vector over the knots."""
        w = self.mean_weights(test, "up", t0, t1)
        return np.array([w.get(param_name("wind_up", str(k)), 0.0)
                         for k in range(len(self.knot_times(test)))])

    def correlation(self, test: FlightTest) -> np.ndarray:
        """The knots' prior correlation under the Gauss-Markov process, phi^|i-j|."""
        k = np.arange(len(self.knot_times(test)))
        return math.exp(-self.knot_s / self.tau_s) ** np.abs(np.subtract.outer(k, k))

    def mean_sigma(self, test: FlightTest, t0: float, t1: float) -> float:
        """The prior's sigma (m/s) of the vertical air motion's mean over [t0, t1] (s):
        sqrt(b' S b), b the window's knot weights (`knot_weights`) and S the knots' prior
        covariance, s^2 phi^|i-j| conditioned on the held mean where there is one
        (`sigma_mean_vertical`; Sherman-Morrison).  What the air may add to or take from
        a steady descent rate measured over that window."""
        cov = self.sigma_vertical**2 * self.correlation(test)
        if self.sigma_mean_vertical is not None:
            a = self.knot_weights(test, test.t_start, test.t_end)
            held = cov @ a
            cov = cov - np.outer(held, held) / (self.sigma_mean_vertical**2 + float(a @ held))
        b = self.knot_weights(test, t0, t1)
        return float(np.sqrt(max(float(b @ cov @ b), 0.0)))

    def sigma(self, component: str) -> float:
        return self.sigma_vertical if component == "up" else self.sigma_horizontal

    def parameters(self, test: FlightTest) -> list[Parameter]:
        return [Parameter(param_name(f"wind_{c}", str(k)), "m/s", 0.0, -MAX_WIND_M_S,
                          MAX_WIND_M_S, scale=self.sigma(c), process_knot=True,
                          description=f"air velocity, {c}, at t = {t:.3f} s")
                for c in self.components for k, t in enumerate(self.knot_times(test))]

    def process_priors(self, test: FlightTest) -> dict[str, tuple[float, float]]:
        """Each knot's time (s) and the process's stationary sigma (m/s): the marginal prior
        of every knot value."""
        return {param_name(f"wind_{c}", str(k)): (float(t), self.sigma(c))
                for c in self.components for k, t in enumerate(self.knot_times(test))}

    def null_values(self, test: FlightTest) -> dict[str, float]:
        """Still air: every knot zero (the prior's residuals are then zero too)."""
        return {p.name: 0.0 for p in self.parameters(test)}

    def air_velocity(self, ctx: ModelContext) -> ca.SX:
        """u(t) (m/s, east-north-up): the knots' hat functions summed (piecewise linear,
        constant beyond the last knot)."""
        knots = self.knot_times(ctx.test)
        u = [ca.SX(0.0)] * 3
        for c in self.components:
            u[COMPONENTS.index(c)] = ctx.time_series(
                f"wind_{c}", knots, [param_name(f"wind_{c}", str(k)) for k in range(len(knots))],
                self.knot_s)
        return ca.vertcat(*u)

    def forces(self, ctx: ModelContext) -> None:
        gust = self.air_velocity(ctx)
        ctx.add_air_velocity(gust, self.name)
        for c in self.components:
            ctx.q[f"air_velocity_{c}"] = gust[COMPONENTS.index(c)]

    def penalties(self, ctx: ModelContext) -> dict[str, tuple[np.ndarray, ca.SX]]:
        """The process prior's standardised innovations, per component at every knot."""
        knots = self.knot_times(ctx.test)
        phi = math.exp(-self.knot_s / self.tau_s)
        spread = math.sqrt(1.0 - phi**2)
        out = {}
        for c in self.components:
            s = self.sigma(c)
            u = [ctx.p[param_name(f"wind_{c}", str(k))] for k in range(len(knots))]
            innovations = [u[0] / s] + [(u[k] - phi * u[k - 1]) / (s * spread)
                                        for k in range(1, len(knots))]
            out[f"wind_{c}"] = (knots, ca.vertcat(*innovations))
        if self.sigma_mean_vertical is not None:
            weights = self.mean_weights(ctx.test, "up", ctx.test.t_start, ctx.test.t_end)
            mean = sum(w * ctx.p[k] for k, w in weights.items())
            mid = np.array([0.5 * (ctx.test.t_start + ctx.test.t_end)])
            out["wind_up_mean"] = (mid, ca.vertcat(mean / self.sigma_mean_vertical))
        return out

    def prior_log_det(self, test: FlightTest) -> float:
        """log det of the knots' prior correlation in their scaled coordinates (u / s per
        component): (K - 1) log(1 - phi^2) per component of K knots (`correlation`), and
        with the mean held (`sigma_mean_vertical`), less log(1 + s^2 a'Ra /
        sigma_mean^2), a the mean's knot weights (the rank-one precision the mean's
        residual adds: the matrix determinant lemma)."""
        knots = self.knot_times(test)
        phi = math.exp(-self.knot_s / self.tau_s)
        out = len(self.components) * (len(knots) - 1) * math.log(1.0 - phi**2)
        if self.sigma_mean_vertical is not None:
            a = self.knot_weights(test, test.t_start, test.t_end)
            spread = float(a @ self.correlation(test) @ a) * self.sigma_vertical**2
            out -= math.log(1.0 + spread / self.sigma_mean_vertical**2)
        return out

    def draw(self, test: FlightTest, rng: np.random.Generator) -> dict[str, float]:
        """Knot values drawn from the process (a simulated test's air motion)."""
        knots = self.knot_times(test)
        phi = math.exp(-self.knot_s / self.tau_s)
        out = {}
        for c in self.components:
            s = self.sigma(c)
            u = s * rng.standard_normal()
            for k in range(len(knots)):
                if k:
                    u = phi * u + s * math.sqrt(1.0 - phi**2) * rng.standard_normal()
                out[param_name(f"wind_{c}", str(k))] = float(u)
        return out
