"""Profile likelihood of one parameter: where the covariance's quadratic picture holds.

For a parameter theta the profile is the best chi-square with theta held at
a value and every other parameter (and the trajectory) re-fitted,

    delta_chi2(theta) = min over the rest of chi^2  -  chi^2 at the fit.

The covariance predicts the parabola ((theta - theta_hat) / sigma)^2.  Where
the model is nearly linear in theta over the interval the two agree; where
it is not (a start time against a flat (t - t_i)^expopen rise, a fill
constant near a bound) the profile is the honest picture, and its 95 %
interval, the values with delta_chi2 <= chi2_1(0.95) = 3.84, replaces the
symmetric theta_hat +- 1.96 sigma.

Each point is solved from the solution of its neighbour nearer the optimum
(continuation outwards on each side), so a profile of n points costs about
n short what-if solves.  A point whose solve fails is reported with its
status and left out of the curve and the interval.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io.model_spec import ModelSpec

LEVEL = 0.95
THRESHOLD = float(chi2.ppf(LEVEL, 1))  # 3.84: the profile's 95 % interval edge


@dataclass
class Profile:
    """delta chi-square along one parameter (SI values), beside its quadratic prediction."""

    name: str
    unit: str
    estimate: float
    std: float
    values: np.ndarray
    delta_chi_square: np.ndarray
    failures: list[tuple[float, str]] = field(default_factory=list)
    # Every parameter's value (SI) at each point, in the order of `values`.
    parameters: list[dict[str, float]] = field(default_factory=list)

    @property
    def quadratic(self) -> np.ndarray:
        """The covariance's prediction ((value - estimate) / std)^2 at the profile's values."""
        return ((self.values - self.estimate) / self.std) ** 2

    def interval(self) -> tuple[float | None, float | None]:
        """The 95 % profile-likelihood interval, interpolated linearly between points; an
        end is None where the profile stays below the threshold over the span studied."""
        below = self.values < self.estimate
        lo = _crossing(self.values[below][::-1], self.delta_chi_square[below][::-1],
                       self.estimate)
        hi = _crossing(self.values[~below], self.delta_chi_square[~below], self.estimate)
        return lo, hi

    def wald_interval(self) -> tuple[float, float]:
        """estimate -+ 1.96 std: the covariance's 95 % interval."""
        half = float(np.sqrt(THRESHOLD)) * self.std
        return self.estimate - half, self.estimate + half

    def as_dict(self) -> dict:
        lo, hi = self.interval()
        return {"unit": self.unit, "estimate": self.estimate, "std": self.std,
                "values": self.values.tolist(), "delta_chi_square": self.delta_chi_square.tolist(),
                "quadratic": self.quadratic.tolist(), "interval95": [lo, hi],
                "wald_interval95": list(self.wald_interval()),
                "failures": [{"value": v, "status": s} for v, s in self.failures]}

    def __str__(self) -> str:
        lo, hi = self.interval()
        wlo, whi = self.wald_interval()
        edge = lambda v: "beyond the span" if v is None else f"{v:.5g}"  # noqa: E731
        line = (f"{self.name}: profile 95 % interval [{edge(lo)}, {edge(hi)}] {self.unit}, "
                f"covariance's [{wlo:.5g}, {whi:.5g}]")
        if self.failures:
            line += f"; {len(self.failures)} point(s) failed: " + ", ".join(
                f"{v:.5g} ({s})" for v, s in self.failures)
        return line


def _crossing(values: np.ndarray, delta: np.ndarray, estimate: float) -> float | None:
    """First value, walking out from the estimate, where delta reaches THRESHOLD."""
    v_prev, d_prev = estimate, 0.0
    for v, d in zip(values, delta, strict=True):
        if d >= THRESHOLD:
            return float(v_prev + (THRESHOLD - d_prev) * (v - v_prev) / (d - d_prev))
        v_prev, d_prev = v, d
    return None


def require_free(est: Estimator, name: str) -> None:
    """InputError unless `name` is a free parameter of `est` (checked before any solve)."""
    if name not in est.free:
        raise InputError("--profile", name, f"a free parameter of the fit ({', '.join(est.free)})")


def profile(est: Estimator, fit: Fit, cov: Covariance, name: str, span: float = 3.0,
            points: int = 13, progress: bool = False) -> Profile:
    """The profile of free parameter `name` over estimate -+ `span` sigma at `points` values
    (clipped to the parameter's bounds), from the fit `fit` of `est`."""
    require_free(est, name)
    std = cov.std.get(name)
    if std is None or name in cov.at_bound or std <= 0.0:
        raise InputError("--profile", name, "a parameter the fit determines (not on a bound, "
                                            "not undetermined)")
    prm = est.model.parameter(name)
    theta = fit.parameters[name]
    offsets = np.linspace(-span, span, points) * std
    grid = np.unique(np.clip(theta + offsets[offsets != 0.0], prm.lower, prm.upper))
    return Profile(name, prm.unit, theta, std,
                   *_continue_outwards(est, fit, fit, name, grid, progress))


def held_profile(fit: Fit, spec: ModelSpec, name: str, grid: np.ndarray,
                 progress: bool = False, max_iter: int | None = None) -> Profile:
    """The profile of `name`, a parameter `fit` (of model `spec`) holds fixed: the model
    refitted with `name` freed and held at each value of `grid` (SI), delta chi-square
    against `fit`; each refit gets `max_iter` Ipopt iterations (default: the fit's).  Its
    std is NaN: a held parameter has no covariance."""
    fixed = {k: v for k, v in fit.settings.fixed.items() if k != name}
    est = Estimator(fit.test, spec, replace(fit.settings, free=[*fit.free, name], fixed=fixed,
                                            max_iter=max_iter or fit.settings.max_iter))
    theta = fit.parameters[name]
    grid = np.unique(np.asarray(grid, dtype=float))
    return Profile(name, est.model.parameter(name).unit, theta, float("nan"),
                   *_continue_outwards(est, fit, est.point_from(fit), name,
                                       grid[grid != theta], progress))


def _continue_outwards(est: Estimator, fit: Fit, start: Fit | np.ndarray, name: str,
                       grid: np.ndarray, progress: bool
                       ) -> tuple[np.ndarray, np.ndarray, list[tuple[float, str]],
                                  list[dict[str, float]]]:
    """Solve `est` with `name` held at each value of `grid`, walking out from the fit's value
    on each side, each solve starting from its inner neighbour's (the first from
    `start`): the values solved (the fit's own included, delta 0), sorted, their chi-square
    above `fit`'s, the values whose solve failed with its status, and every parameter at
    each value solved."""
    theta = fit.parameters[name]
    values, deltas, failures, params = [theta], [0.0], [], [dict(fit.parameters)]
    for side in (grid[grid > theta], grid[grid < theta][::-1]):
        inner = start
        for v in side:
            if progress:
                print(f"\rprofile {name}: {len(values) + len(failures)}/{grid.size + 1} "
                      f"points", end="", file=sys.stderr, flush=True)
            try:
                held = est.solve(start=inner, bounds={name: (float(v), float(v))},
                                 sensitivities=False)
            except SolverFailure as exc:
                failures.append((float(v), f"{exc.status} after {exc.iterations} iterations"))
                continue
            values.append(float(v))
            deltas.append(held.chi_square - fit.chi_square)
            params.append(dict(held.parameters))
            inner = held
    if progress:
        print(file=sys.stderr)
    order = np.argsort(values)
    return (np.asarray(values)[order], np.asarray(deltas)[order], failures,
            [params[i] for i in order])
