"""Two effect sets fitted to the same test: which one do the data prefer, and by how much?

Both models are fitted to the same residuals with the same sigmas, so their
chi-squares are -2 log-likelihoods up to a common constant.  With k free
parameters and n residuals:

* AIC = chi^2 + 2k and BIC = chi^2 + k ln n (lower is better; they need no
  nesting);
* where model A is nested in model B (B is A plus effects that reduce to
  nothing at null values of their parameters), the likelihood-ratio statistic
  LR = chi^2_A - chi^2_B follows chi-square on k_B - k_A degrees of freedom
  under A, or chi-bar-squared where a null value is a parameter bound
  (`hypothesis_tests`).

`refit` fits a model starting from another model's fit (states, parameters
and captured speeds carried over by name), which is how an effect is added
to a fit without starting again from the offline reduction.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.continuation import solve
from cpas_ocp.inference.hypothesis_tests import chi_bar_square_sf
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.model import Model


@dataclass(frozen=True)
class Criteria:
    """Goodness of one fit: chi-square, free parameters k, residuals n, AIC and BIC.

    k counts the free parameters (those held on a bound included), not the
    shooting states; both criteria drop the constant sum of log sigma.
    """

    chi_square: float
    k: int
    n: int

    @property
    def aic(self) -> float:
        return self.chi_square + 2.0 * self.k

    @property
    def bic(self) -> float:
        return self.chi_square + self.k * math.log(self.n)

    @classmethod
    def of(cls, fit: Fit) -> Criteria:
        return cls(fit.chi_square, len(fit.free), fit.n_samples)


@dataclass(frozen=True)
class LikelihoodRatio:
    """LR = chi^2 of the smaller model minus chi^2 of the larger, on `dof` added parameters
    of which `one_sided` sit on a bound at their null values.

    With `lower_bound`, the larger model's chi-square is that of a feasible
    point rather than of its optimum (a refit that did not converge), so LR is
    at least `statistic` and the p-value at most `p_value`: a conservative test.
    """

    statistic: float
    dof: int
    one_sided: int = 0
    lower_bound: bool = False

    @property
    def p_value(self) -> float:
        return chi_bar_square_sf(max(self.statistic, 0.0), self.dof - self.one_sided,
                                 self.one_sided)

    def as_dict(self) -> dict[str, Any]:
        """The test as JSON holds it, with its p-value (which `from_dict` recomputes)."""
        return {**dataclasses.asdict(self), "p_value": self.p_value}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> LikelihoodRatio | None:
        """The test `as_dict` wrote (None for None)."""
        if data is None:
            return None
        return cls(data["statistic"], data["dof"], data["one_sided"], data["lower_bound"])

    def __str__(self) -> str:
        sided = f", {self.one_sided} one-sided" if self.one_sided else ""
        at_least, at_most = (">= ", "<= ") if self.lower_bound else ("", "= ")
        return (f"likelihood ratio {at_least}{self.statistic:.2f} on {self.dof} dof{sided}: "
                f"p {at_most}{self.p_value:.3g}")


def nested_start(fit: Fit, spec: ModelSpec, free: list[str] | None = None,
                 values: dict[str, float] | None = None,
                 max_iter: int | None = None
                 ) -> tuple[Estimator, np.ndarray, tuple[float, float]]:
    """The estimator of `spec` on `fit`'s test and grid, its start at `fit`, and the
    start's chi-square and largest scaled gap (`Estimator.extension_start`).

    `free`: the parameters to estimate (default: the spec's choice); their
    start values are the fit's where it has them, else `values` (SI), else the
    new model's defaults.  `max_iter`: Ipopt's iteration limit (default: the fit's).
    """
    model = spec.model(fit.test)
    names = free if free is not None else spec.free_names(model)
    start = {n: fit.parameters[n] for n in names if n in fit.parameters}
    start.update({n: v for n, v in (values or {}).items() if n in names})
    guess = {**(nested_values(fit, model, names) or {}), **start}
    settings = dataclasses.replace(fit.settings, free=list(names), guess=guess, limits={},
                                   fixed={}, max_iter=max_iter or fit.settings.max_iter)
    est = Estimator(fit.test, spec, settings)
    return est, *est.extension_start(fit, start)


def nested_values(fit: Fit, model: Model, free: Sequence[str]) -> dict[str, float] | None:
    """Every parameter of `model` (estimating `free`) as it starts when nested around `fit`:
    the fit's value where the fit has the parameter, the model's default where not.  None
    where `free` leaves out a parameter the fit estimated: such a model is not nested
    around the fit, and holds that parameter where its own offline reduction puts it.

    The values the fit holds are those its own start had (the reduction's, or a spec's),
    and the reduction sets only the baseline's parameters, which every fit has; a new
    effect's parameters it leaves at their defaults.  So these are the values the
    reduction would give, without running it (2.3 s a refit on `drogue`, a third of the
    estimator's build)."""
    if any(n in fit.free and n not in free for n in model.parameter_names):
        return None
    return {n: fit.parameters.get(n, model.parameter(n).default) for n in model.parameter_names}


def refit(fit: Fit, spec: ModelSpec, free: list[str] | None = None,
          values: dict[str, float] | None = None, progress: bool = False,
          max_iter: int | None = None) -> tuple[Estimator, Fit]:
    """Fit `spec` to `fit`'s test on the same grid, starting from `fit` (`nested_start`,
    which see for the arguments); the estimator (for the covariance) and the new fit.
    Raises SolverFailure when the solve fails.
    """
    est, z0, _ = nested_start(fit, spec, free, values, max_iter)
    return est, est.solve(progress=progress, start=z0)


def one_sided_count(spec: ModelSpec, fit: Fit, null: dict[str, float]) -> int:
    """How many of the null values in `null` are bounds of their parameters."""
    model = spec.model(fit.test)
    return sum(model.parameter(name).on_bound(value) for name, value in null.items())


def channel_rms(fit: Fit) -> dict[str, float]:
    """Normalised residual RMS per sensor channel (``sensor.channel``)."""
    return {f"{r.sensor}.{r.channel}": float(np.sqrt(np.mean(r.normalised**2)))
            for r in fit.residuals}


@dataclass
class Comparison:
    """Two models fitted to one test: `fits[0]` with `specs[0]`, `fits[1]` with `specs[1]`.

    `lr` is the likelihood-ratio test of the smaller model against the larger
    where one is nested in the other (`nesting`), else None; `note` says which
    way the nesting goes, or why there is none.
    """

    labels: tuple[str, str]
    specs: tuple[ModelSpec, ModelSpec]
    fits: tuple[Fit, Fit]
    covariances: tuple[Covariance, Covariance]
    lr: LikelihoodRatio | None
    note: str

    @property
    def criteria(self) -> tuple[Criteria, Criteria]:
        return Criteria.of(self.fits[0]), Criteria.of(self.fits[1])


def nesting(spec_small: ModelSpec, spec_large: ModelSpec, fit_small: Fit, fit_large: Fit
            ) -> tuple[int, int] | None:
    """(added parameters, how many of them are one-sided) when the first model is nested in
    the second, else None.

    Nested: every effect of the first is in the second (or replaced there by
    an effect that `replaces` it), each added effect has null values
    (`Effect.null_values`), and the second's free parameters include the first's.
    """
    large = {e.name: e for e in spec_large.effects}
    replaced = {e.replaces: e for e in spec_large.effects if e.replaces}
    small_names = {e.name for e in spec_small.effects}
    if not all(n in large or n in replaced for n in small_names):
        return None
    if not set(fit_small.free) <= set(fit_large.free):
        return None
    null: dict[str, float] = {}
    for name, effect in large.items():
        if name in small_names:
            continue
        values = effect.null_values(fit_large.test)
        if values is None:
            return None
        null.update({k: v for k, v in values.items() if k in fit_large.free})
    dof = len(fit_large.free) - len(fit_small.free)
    return dof, min(one_sided_count(spec_large, fit_large, null), dof)


def compare(fit_a: Fit, cov_a: Covariance, spec_a: ModelSpec, spec_b: ModelSpec,
            labels: tuple[str, str], progress: bool = False) -> Comparison:
    """Fit `spec_b` from `fit_a` (`refit`; from its own offline reduction if that fails) and
    compare the two; `cov_a` is `fit_a`'s covariance."""
    try:
        est_b, fit_b = refit(fit_a, spec_b, progress=progress)
    except SolverFailure:
        settings = dataclasses.replace(fit_a.settings, free=None, guess={}, fixed={}, limits={})
        est_b = Estimator(fit_a.test, spec_b, settings)
        fit_b = solve(est_b, progress=progress)
    lr, note = None, "neither model is nested in the other; compare AIC and BIC"
    fits = (fit_a, fit_b)
    for small, large, s_spec, l_spec in ((0, 1, spec_a, spec_b), (1, 0, spec_b, spec_a)):
        nested = nesting(s_spec, l_spec, fits[small], fits[large])
        if nested is not None and nested[0] > 0:
            lr = LikelihoodRatio(fits[small].chi_square - fits[large].chi_square, *nested)
            note = f"{labels[small]} is nested in {labels[large]}"
            break
    return Comparison(labels, (spec_a, spec_b), fits, (cov_a, est_b.covariance(fit_b)), lr,
                      note)
