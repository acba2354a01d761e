"""A hierarchical reconstruction: every test's trajectory and a parameter's population in one NLP.

The two-stage population (`campaign.population_model`) summarises each test
by its estimate and covariance, then fits the population to those.  Where a
test barely determines a parameter its estimate is far from Gaussian and its
covariance says little, and the population's intervals come out wide.  Here
every test's data and the population are one likelihood
(`estimation.hierarchical_nlp`): each test's copy of a parameter named in
`populations` is log p_i = mu + eta_i with eta_i ~ N(0, tau^2), mu a decision
variable of the joint NLP.

tau is estimated by an outer loop: for each tau the NLP is solved (its
minimum is the joint mode of the tests' parameters and mu) and the Laplace
approximation to the tests' marginal likelihood is evaluated from the
Gauss-Newton Hessian at that mode (`HierarchicalNlp.laplace_deviance`,
integrating every free coordinate, mu among them: the restricted likelihood's
analogue).  tau minimises it on a bounded interval of log tau, one
population at a time (coordinate passes where there are several).

mu's interval at the estimated tau is Student-t on (copies - 1) degrees of
freedom with the KKT covariance's sigma of mu (tau's own uncertainty is not
propagated into it).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Settings, SolverStats
from cpas_ocp.estimation.fit import Fit
from cpas_ocp.estimation.hierarchical_nlp import HierarchicalNlp, Population
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.joint_fit import (
    SharedEstimate,
    SharingError,
    fit_problems,
    fits_alone,
    start_value,
)
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.parameters import split_name

# tau's search interval (log space): from 0.001 % (a test may fix a drag area to 0.1 %) to a
# factor e.
TAU_RANGE = (1e-5, 1.0)
# A tau's start where the copies' own spread says nothing: 5 %.
TAU_START = 0.05
LEVEL = 0.95
# A tau within this (log) of an edge of TAU_RANGE is at it: Brent's tolerance.
EDGE = 0.02


@dataclass(frozen=True)
class PopulationEstimate:
    """One population's estimate: the median exp(mu) (SI) with its interval at LEVEL, tau
    (log space), and each copy's value at the joint mode (SI)."""

    name: str
    median: float
    lower: float
    upper: float
    mu_std: float
    tau: float
    copies: dict[str, float]
    tau_estimated: bool = True  # False where the caller held it


@dataclass
class HierarchicalFit:
    """Several tests and their parameters' populations reconstructed in one NLP."""

    labels: list[str]
    fits: list[Fit]
    individual: list[Fit]
    individual_covariances: list[Covariance]
    populations: list[PopulationEstimate]
    shared: list[SharedEstimate]
    covariance: Covariance
    stats: SolverStats
    deviance: float
    evaluations: int
    chi2: float  # every residual at the joint mode, the copies' among them
    dof: int  # those residuals less the free parameters (each copy and mean counted)

    @property
    def problems(self) -> list[str]:
        """Why the fit is not a result (empty where it is): `joint_fit.fit_problems` (a
        chi-square beyond the noise, a median or shared parameter undetermined, a
        parameter at a bound), and a tau whose search ended at an edge of TAU_RANGE (not
        determined within it)."""
        undetermined = [p.name for p in [*self.populations, *self.shared]
                        if not np.isfinite(p.mu_std if isinstance(p, PopulationEstimate)
                                           else p.std)]
        out = fit_problems(self.chi2, self.dof, undetermined, self.covariance)
        edge = [p.name for p in self.populations if p.tau_estimated
                and min(abs(np.log(p.tau / edge)) for edge in TAU_RANGE) < EDGE]
        if edge:
            out.append(f"tau at an edge of its search range {TAU_RANGE}: {', '.join(edge)}")
        return out

    @property
    def is_result(self) -> bool:
        return not self.problems

    def estimate(self, name: str) -> PopulationEstimate | SharedEstimate:
        """The population or shared parameter `name`'s estimate."""
        for p in [*self.populations, *self.shared]:
            if p.name == name:
                return p
        raise KeyError(f"no population or shared parameter {name!r}; populations: "
                       f"{[p.name for p in self.populations]}, shared: "
                       f"{[s.name for s in self.shared]}")


def _start_tau(values: np.ndarray, variances: np.ndarray) -> float:
    """The copies' spread in log space beyond their own variance (a moment estimate),
    within TAU_RANGE."""
    excess = float(np.var(values, ddof=1) - np.mean(variances)) if values.size > 1 else 0.0
    tau = np.sqrt(excess) if excess > 0.0 else TAU_START
    return float(np.clip(tau, *TAU_RANGE))


def _downhill(f: Callable[[float], float], x0: float, bounds: np.ndarray,
              step: float = np.log(2.0)) -> float:
    """The minimum of `f` within `bounds`, from `x0`: steps of `step` downhill until `f`
    rises or a bound is reached (each solve warm-started from its neighbour's, a path on
    which the NLP changes little at a time), then Brent's bounded search within the last
    bracket."""
    lo, hi = float(bounds[0]), float(bounds[1])
    x, fx = x0, f(x0)
    direction = 1.0
    nxt = min(x + step, hi)
    f_next = f(nxt) if nxt > x else np.inf
    if f_next >= fx:
        direction, nxt = -1.0, max(x - step, lo)
        f_next = f(nxt) if nxt < x else np.inf
    behind = x
    while f_next < fx:
        behind, x, fx = x, nxt, f_next
        nxt = float(np.clip(x + direction * step, lo, hi))
        if nxt == x:
            return x
        f_next = f(nxt)
    a, b = sorted((behind, nxt))
    if b - a <= 0.02:
        return x
    found = optimize.minimize_scalar(f, bounds=(a, b), method="bounded",
                                     options={"xatol": 0.02})
    return float(found.x) if found.fun < fx else x


def hierarchical_fit(tests: Sequence[FlightTest], populations: Mapping[str, str],
                     share: Mapping[str, str] | None = None, settings: Settings | None = None,
                     labels: Sequence[str] | None = None,
                     tau: Mapping[str, float] | None = None,
                     progress: Callable[[str], None] | None = None,
                     monitor: bool = True, warm: bool = True) -> HierarchicalFit:
    """Reconstruct `tests` in one NLP with each parameter named in `populations` (base name
    -> "type" or "vehicle", as `joint_fit`'s share) drawn per test from a log-normal
    population (module docstring), and each named in `share` held equal across the tests
    as `joint_fit` holds it.  `tau` holds a population's tau (log space) fixed instead of
    estimating it.  `monitor` and `warm` False end each solve by Ipopt's own
    acceptable-point tests before the statistical one and start each from Ipopt's default
    barrier (`JointNlp.solve`: the slower path, kept to compare).
    Raises SolverFailure where a solve fails (its status and
    iterations), SharingError where nothing named has copies in two places."""
    say = progress or (lambda _: None)
    labels = list(labels) if labels is not None else [t.name for t in tests]
    share = dict(share or {})
    overlap = set(share) & set(populations)
    if overlap:
        raise SharingError(f"{', '.join(sorted(overlap))}: either shared or drawn from a "
                           "population, not both")
    ests, links, fits, covs = fits_alone(tests, {**populations, **share}, settings, labels,
                                         say)
    held = [k for k in links if split_name(k.members[0][1])[0] in share]
    drawn = [k for k in links if k not in held]
    pops, means = [], {k.name: start_value(k, fits, covs) for k in held}
    for link in drawn:
        values = np.array([fits[t].parameters[n] for t, n in link.members])
        if (values <= 0.0).any():
            raise ValueError(f"{link.name}: a log-normal population needs positive copies")
        variances = np.array([covs[t].std.get(n, np.inf) ** 2 for t, n in link.members])
        variances = np.where(np.isfinite(variances), variances / values**2, np.nan)
        known = np.isfinite(variances)
        logs = np.log(values)
        start = (tau or {}).get(link.name) or _start_tau(logs[known], variances[known])
        pops.append(Population(link.name, link.members, start))
        means[link.name] = float(np.mean(logs))
    nlp = HierarchicalNlp(ests, pops, held)
    z = nlp.start(fits, means)
    free = [g for g, p in enumerate(pops) if p.name not in (tau or {})]
    state = {"z": z, "evaluations": 0}
    # each solve after the first starts at its neighbour's solution (a warm start)

    def solve() -> tuple[np.ndarray, SolverStats]:
        """The NLP at its current tau from the last solution; a warm start that fails
        (a restoration phase at the small barrier) is solved again from the default one."""
        if not (warm and state["evaluations"] > 0):
            return nlp.solve(state["z"], monitor=monitor)
        try:
            return nlp.solve(state["z"], monitor=monitor, warm=True)
        except SolverFailure as exc:
            say(f"warm start failed ({exc.status}); solving from the default barrier")
            return nlp.solve(state["z"], monitor=monitor)

    def deviance(log_taus: np.ndarray) -> float:
        nlp.set_tau(np.exp(log_taus))
        z, _ = solve()
        state["z"] = z
        state["evaluations"] += 1
        value = nlp.laplace_deviance(z)
        say(f"tau {', '.join(f'{np.exp(v):.4g}' for v in log_taus)}: deviance {value:.3f}")
        return value

    log_taus = np.log([p.tau for p in pops])
    for _ in range(2 if len(free) > 1 else 1):
        for g in free:
            def along(v: float, g: int = g) -> float:
                trial = log_taus.copy()
                trial[g] = v
                return deviance(trial)
            log_taus[g] = _downhill(along, float(log_taus[g]), np.log(TAU_RANGE))
    nlp.set_tau(np.exp(log_taus))
    z, solver_stats = solve()
    final = nlp.laplace_deviance(z)
    cov = nlp.covariance(z)
    out = []
    for g, pop in enumerate(nlp.populations):
        mu = float(z[nlp.mean_columns[g]])
        sd = cov.std.get(f"mu:{pop.name}", np.nan)
        half = stats.t.ppf(0.5 + LEVEL / 2, max(len(pop.members) - 1, 1)) * sd
        copies = {f"{t}:{n}": float(z[nlp.column(t, n)] * nlp.scale(t, n))
                  for t, n in pop.members}
        out.append(PopulationEstimate(pop.name, float(np.exp(mu)), float(np.exp(mu - half)),
                                      float(np.exp(mu + half)), sd, pop.tau, copies,
                                      g in free))
    shared = []
    for link in held:
        t, name = link.members[0]
        shared.append(SharedEstimate(link.name, float(z[nlp.column(t, name)]
                                                      * nlp.scale(t, name)),
                                     cov.std.get(f"{t}:{name}", np.nan), link.members))
    r = nlp.residual_value(z)
    n_free = len(nlp.names) - sum(len(k.members) - 1 for k in held)
    return HierarchicalFit(labels, nlp.fits(z, solver_stats), fits, covs, out, shared, cov,
                           solver_stats, final, state["evaluations"], float(r @ r),
                           r.size - n_free)
