"""Do the data want the air's motion?  The Bayes factor of a wind process over still air.

The wind process (`effects.wind_process`) has a parameter per knot, held in
check by its Gauss-Markov prior, so the likelihood-ratio and score tests of
the diagnosis, which count free parameters, do not apply to it.  The
question "is there air motion?" is a comparison of two models by their
evidence: still air is the process at intensity s -> 0, whose Laplace
evidence is the still-air fit's own,

    -2 log p(y | still) = chi^2_still + log det(J'J)_scaled,

and the process's is `process_intensity.evidence` at the intensity the
evidence prefers on a grid (each fit started from the one before, the first
from the still-air fit: the knots start at zero).  The two share every
constant (the same grid, the same parameter scales), so their difference is
2 ln B, B the Bayes factor of air motion over still air.  The diagnosis
names the process when 2 ln B >= DECISIVE_2LNB (10: "very strong" on Kass
and Raftery's 1995 scale, odds of 150 to 1).

It is asked only where the residuals point at the vehicle's own motion:
where an altimeter and a GPS, whose errors share nothing, share a slow
wander (`common_residual`, Fisher's p below the diagnosis's level).  A
process can absorb slow residuals that other effects explain (an opening
load, a sensor lag); asked everywhere, it would be named in their place.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from cpas_ocp.discrepancy.common_residual import combined_p_value, common_residuals
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.inference.model_comparison import nested_start, refit
from cpas_ocp.inference.process_intensity import IntensityPoint, sweep_intensity
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.wind_process import WindProcess

DECISIVE_2LNB = 10.0  # 2 ln B from which the data decisively want the air's motion
INTENSITY_GRID = (0.5, 1.0, 2.0)  # factors of the candidate's sigma tried, smallest first
# The process a phase is tested with: knots this many per correlation time, and a correlation
# time of this fraction of the phase, within TAU_RANGE_S (s).
KNOTS_PER_TAU = 5
TAU_FRACTION = 0.1
TAU_RANGE_S = (5.0, 20.0)


@dataclass
class WindEvidence:
    """The evidence of still air and of the candidate process over its intensity grid."""

    process: WindProcess
    still: float  # -2 log evidence of the still-air fit
    points: list[IntensityPoint]
    common_p: float  # Fisher's p of the altitude sensors' shared residual
    best_fit: Fit | None = None
    best_spec: ModelSpec | None = None  # the model of `best_fit`: the process at its sigma

    @property
    def best(self) -> IntensityPoint | None:
        done = [p for p in self.points if p.evidence is not None]
        return min(done, key=lambda p: p.evidence) if done else None

    @property
    def two_ln_b(self) -> float | None:
        """2 ln B of the best intensity over still air (None where no fit converged)."""
        best = self.best
        return None if best is None else self.still - best.evidence

    @property
    def decisive(self) -> bool:
        value = self.two_ln_b
        return value is not None and value >= DECISIVE_2LNB

    def verdict(self) -> str:
        """The clause the diagnosis's verdict names the process with."""
        best, fit = self.best, self.best_fit
        assert best is not None and fit is not None
        return (f"wind_process, the air's vertical motion (2 ln B = {self.two_ln_b:.1f} over "
                f"still air at sigma {best.sigma_vertical:.3g} m/s, at least "
                f"{DECISIVE_2LNB:g} decides; chi-square {best.chi_square:.1f}, chi-square/dof "
                f"{fit.chi_square / fit.dof:.2f})")


def candidate_process(fit: Fit) -> WindProcess:
    """The process a phase is tested with: vertical (what altitude sensors see), tau a tenth
    of the phase within TAU_RANGE_S, knots KNOTS_PER_TAU per tau, sigma 1 m/s."""
    duration = fit.test.t_end - fit.test.t_start
    tau = min(max(TAU_FRACTION * duration, TAU_RANGE_S[0]), TAU_RANGE_S[1])
    return WindProcess(components=("up",), knot_s=tau / KNOTS_PER_TAU, tau_s=tau,
                       sigma_vertical=1.0)


def wind_evidence(fit: Fit, spec: ModelSpec, alpha: float, progress: bool = False
                  ) -> WindEvidence | None:
    """The evidence for the air's motion at `fit` (made with `spec`, which has no wind
    process); None where the altitude sensors share no residual at level `alpha` or the
    test has no pair of them to tell."""
    if any(isinstance(e, WindProcess) for e in spec.effects):
        return None
    found = common_residuals(fit)
    if not found or (p_common := combined_p_value(found)) >= alpha:
        return None
    est_still, _, _ = nested_start(fit, spec, free=list(fit.free))
    still = fit.chi_square + est_still.information_log_det(fit)
    process = candidate_process(fit)
    # Each intensity's fit starts from the one before, the first from the still-air fit.
    found = sweep_intensity(dataclasses.replace(spec, effects=(process, *spec.effects)),
                            INTENSITY_GRID, lambda scaled, previous: refit(previous or fit,
                                                                           scaled), progress)
    return WindEvidence(process, still, found.points, p_common,
                        *((None, None) if found.best is None
                          else (found.best[2], found.best[1].spec)))
