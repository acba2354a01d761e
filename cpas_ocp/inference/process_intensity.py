"""The wind process's intensity chosen by the data: the Laplace-approximated marginal
likelihood over a grid of intensities.

The wind process (`effects.wind_process`) puts a Gaussian prior on its knots
u: N(0, S), S = s^2 R per component, R_ij = phi^|i-j|.  Given s, the evidence
of the data integrates the knots out (and, with a flat prior, every other
free coordinate).  With the knots in the estimator's scaled coordinates
w = u / s (the knots' `Parameter.scale` is s), the prior is N(0, R) in w and
the Laplace approximation about the fit gives

    -2 log p(y | s) = chi^2_min(s) + log det R + log det(J'J)_scaled + const,

chi^2_min the fit's chi-square (data and the process's innovations,
u'S^-1 u), (J'J)_scaled the Gauss-Newton information of every free
coordinate in the scaled decision vector on the constraints' null space
(`Estimator.information_log_det`), and log det R = (K - 1) log(1 - phi^2)
per component of K knots (less the held mean's rank-one term where the process
holds its vertical mean, `WindProcess.prior_log_det`).  The Jacobian of u = s w cancels the s^K of
det S^1/2.  A larger s lowers chi^2_min (the wind explains more) and pays in
the volume term (the posterior is wider than the data make it): the
trade-off is Occam's, so s is not a free knob that absorbs everything, and
in still air the smallest intensity of the grid wins.

The vertical and horizontal intensities keep the ratio the model gives
them; the grid scales both.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from dataclasses import dataclass

from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.wind_process import WindProcess
from cpas_ocp.physics.flight_test import FlightTest


@dataclass(frozen=True)
class IntensityPoint:
    """One intensity of the grid: the vertical and horizontal s (m/s), the fit's chi-square,
    and -2 log evidence (up to a constant; None where the fit failed)."""

    sigma_vertical: float
    sigma_horizontal: float
    chi_square: float | None
    evidence: float | None
    note: str = ""


@dataclass
class IntensityChoice:
    """The grid, the intensity with the largest evidence, its estimator and fit."""

    points: list[IntensityPoint]
    best: IntensityPoint
    estimator: Estimator
    fit: Fit
    horizontal: bool = True  # whether the process has horizontal components

    def summary(self) -> str:
        """One line: the intensity chosen, of which."""
        grid = ", ".join(f"{p.sigma_vertical:g}" for p in self.points)
        return (f"wind-process intensity chosen by marginal likelihood: vertical "
                f"{self.best.sigma_vertical:g} m/s of {grid} m/s")


def wind_effect(spec: ModelSpec) -> WindProcess:
    """The spec's wind process; InputError where it has none."""
    found = [e for e in spec.effects if isinstance(e, WindProcess)]
    if not found:
        raise InputError(spec.source, "model.effects", "a wind_process effect whose "
                         "intensity to choose")
    return found[0]


def without_wind(spec: ModelSpec, test: FlightTest) -> ModelSpec | None:
    """`spec` in still air (its wind process taken out); None where it has none."""
    kept = tuple(e for e in spec.effects if not isinstance(e, WindProcess))
    if len(kept) == len(spec.effects):
        return None
    names = {p.name for e in spec.effects if isinstance(e, WindProcess)
             for p in e.parameters(test)}
    return dataclasses.replace(
        spec, effects=kept, fix={k: v for k, v in spec.fix.items() if k not in names},
        free=tuple(n for n in spec.free if n not in names),
        priors={k: v for k, v in spec.priors.items() if k not in names})


def evidence(est: Estimator, fit: Fit) -> float:
    """-2 log evidence of `fit`'s wind-process intensity, up to a constant (see the module
    docstring)."""
    wind = wind_effect(est.spec)
    return fit.chi_square + wind.prior_log_det(est.test) + est.information_log_det(fit)


FitAt = Callable[[ModelSpec, Fit | None], tuple[Estimator, Fit]]


@dataclass
class IntensitySweep:
    """The grid's points in order, and the estimator and fit of the one with the largest
    evidence (None where every fit failed, `failure` the last one's)."""

    points: list[IntensityPoint]
    best: tuple[IntensityPoint, Estimator, Fit] | None
    failure: SolverFailure | None


def sweep_intensity(spec: ModelSpec, factors: tuple[float, ...], fit_at: FitAt,
                    progress: bool = False) -> IntensitySweep:
    """Fit `spec` with its wind process's intensities scaled by each of `factors`, in order:
    `fit_at(scaled spec, the previous intensity's fit or None)` gives each estimator and
    fit (SolverFailure where it fails), and each is scored by its evidence."""
    wind = wind_effect(spec)
    horizontal = any(c != "up" for c in wind.components)
    out = IntensitySweep([], None, None)
    previous: Fit | None = None
    for factor in factors:
        scaled = dataclasses.replace(wind, sigma_vertical=factor * wind.sigma_vertical,
                                     sigma_horizontal=factor * wind.sigma_horizontal)
        sigmas = (scaled.sigma_vertical, scaled.sigma_horizontal if horizontal else 0.0)
        effects = tuple(scaled if e is wind else e for e in spec.effects)
        try:
            est, fit = fit_at(dataclasses.replace(spec, effects=effects), previous)
        except SolverFailure as exc:
            out.failure = exc
            out.points.append(IntensityPoint(*sigmas, None, None, f"fit failed ({exc.status})"))
            continue
        point = IntensityPoint(*sigmas, fit.chi_square, evidence(est, fit))
        out.points.append(point)
        if progress:
            print(f"  vertical {point.sigma_vertical:.3g} m/s: -2 log evidence "
                  f"{point.evidence:.1f}", file=sys.stderr, flush=True)
        if out.best is None or point.evidence < out.best[0].evidence:
            out.best = (point, est, fit)
        previous = fit
    return out


def choose_intensity(test: FlightTest, spec: ModelSpec, factors: tuple[float, ...],
                     progress: bool = False) -> IntensityChoice:
    """Fit `spec` with its wind process's intensities scaled by each of `factors`, each from
    the offline reduction (`solve_checked`); the one with the largest evidence is chosen."""
    def from_reduction(scaled: ModelSpec, _: Fit | None) -> tuple[Estimator, Fit]:
        est, fit, _claim = solve_checked(Estimator(test, scaled))
        return est, fit

    found = sweep_intensity(spec, factors, from_reduction, progress)
    if found.best is None:
        assert found.failure is not None
        raise found.failure  # every intensity's fit failed: the last one's status
    return IntensityChoice(found.points, *found.best,
                           horizontal=any(c != "up" for c in wind_effect(spec).components))
