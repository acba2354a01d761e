"""The one path from a built estimator to a reconstruction: the fit, what it may claim, and
its covariance.

Every workflow that fits a test takes it: the Python interface
(`api.fit_estimator`), each command, a campaign's worker and the Monte Carlo
study's fit.  The fit comes from the offline reduction, with the start windows
the data press against moved and the opening shapes left on guessed bounds
restarted (`continuation.solve_checked`), or, given wind-intensity factors, the
wind process fitted at each and the one of largest evidence kept
(`process_intensity.choose_intensity`).  Then the covariance (Gauss-Newton or the
exact Hessian of the Lagrangian, optionally scaled by chi-square/dof) and the
drag-area part of the claim, which needs it (`result_claim.check_drag_areas`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.inference.process_intensity import IntensityChoice, choose_intensity
from cpas_ocp.inference.result_claim import Claim, check_claim, check_drag_areas


@dataclass
class Fitted:
    """A fit with its covariance and claim, the estimator that made it (after any window
    moves), and the intensity choice where one was made."""

    estimator: Estimator
    fit: Fit
    covariance: Covariance
    claim: Claim
    intensity_choice: IntensityChoice | None = None


def fit_and_claim(est: Estimator, rescale_sigmas: bool = False, hessian: str = "gauss-newton",
                  wind_intensities: Sequence[float] = (), progress: bool = False) -> Fitted:
    """Fit `est` and judge the fit (module docstring).  `hessian`: "gauss-newton" or
    "exact"; `rescale_sigmas` multiplies the covariance by chi-square/dof.  Raises
    SolverFailure where no fit converges."""
    choice = None
    if wind_intensities:
        choice = choose_intensity(est.test, est.spec, tuple(wind_intensities), progress=progress)
        est, fit = choice.estimator, choice.fit
        claim = check_claim(est, fit)
        claim.notes.append(choice.summary())
    else:
        est, fit, claim = solve_checked(est, progress=progress)
    cov = est.covariance(fit, rescale_sigmas, hessian)
    return Fitted(est, fit, cov, check_drag_areas(claim, fit, cov), choice)
