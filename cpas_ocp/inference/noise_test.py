"""Whether a fit is consistent with the sensor noise: its overall chi-square and every
window's, each against its own chi-square law.

"No candidate effect is significant" is not "consistent with the noise".  A fit
can leave a misfit that no effect tested explains: on a two-Drogue test flown
with a GPS latency and added mass, a chain that found both and one more ended at
chi-square 6,626.7 on 5,723 degrees of freedom, a tail probability of 1e-16
(8.5 sigma), and its worst window held 281.7 on 52 samples.  Only a fit that
passes this test may be called consistent with the noise.

The overall test is two-sided: the fit's total on its degrees of freedom,
against each tail of its chi-square law at alpha / 2.  Above the upper tail the
model or the noise is wrong (a misfit, or sigma stated too small); below the
lower one the residuals are smaller than the stated noise allows: the sigma are
stated too large, or the samples are fewer than counted (noise correlated in
time, as a recorder's filter makes it).  Only the upper tail is a misfit: a
chi-square/dof of 0.669 on 47 degrees of freedom (upper tail 0.96, lower 0.04)
is consistent with the noise, and on 3,000 it lies far below it; neither is a
misfit, and neither says the sigma are "18 % too small".
Each phase window of at least `MIN_TESTED_SAMPLES` samples is tested on its own
samples at alpha / m (Bonferroni over the m windows tested), on the upper tail:
a window quieter than the noise is no misfit of the model there.  Smaller
windows count in the total only (`diagnostics.MIN_TESTED_SAMPLES` says why).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from scipy.stats import chi2 as chi2_law

from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.inference.diagnostics import (
    MIN_TESTED_SAMPLES,
    WindowStatistic,
    window_p_value,
)


@dataclass(frozen=True)
class NoiseTest:
    """The fit's chi-square against the noise: total, degrees of freedom, upper-tail
    probability (`p_value`), the level, and the windows that fail their own test (worst
    first)."""

    chi_square: float
    dof: int
    p_value: float
    alpha: float
    windows_tested: int
    failing: list[WindowStatistic] = field(default_factory=list)

    @property
    def p_below(self) -> float:
        """The lower-tail probability of the total: how often the stated noise gives a
        chi-square this small or smaller."""
        return float(chi2_law.cdf(self.chi_square, self.dof)) if self.dof > 0 else 1.0

    @property
    def above(self) -> bool:
        """Whether the chi-square lies above the noise: the total's upper tail below
        alpha / 2, or a window that fails its own test."""
        return self.p_value < self.alpha / 2.0 or bool(self.failing)

    @property
    def below(self) -> bool:
        """Whether the total lies below the noise (its lower tail below alpha / 2) with no
        window above it: the stated sigma too large, or fewer independent samples than
        counted."""
        return not self.above and self.p_below < self.alpha / 2.0

    @property
    def passes(self) -> bool:
        """Whether the total, on both tails, and every window tested are consistent with
        the noise."""
        return not self.above and not self.below

    @property
    def sigma_scale(self) -> float:
        """sqrt(chi2/dof): the factor by which the stated sigma would have to be multiplied
        for the total to sit at its expectation (below 1: stated too large)."""
        return (self.chi_square / self.dof) ** 0.5 if self.dof > 0 else 1.0

    @property
    def sigmas(self) -> float:
        """How far the total lies above its expectation, in the spread the noise gives it
        (sqrt(2 dof)): 0 on average for a fit at the noise."""
        return (self.chi_square - self.dof) / (2.0 * self.dof) ** 0.5 if self.dof > 0 else 0.0

    def __str__(self) -> str:
        """One line: the total's test and the windows that fail."""
        line = (f"chi-square {self.chi_square:.1f} on {self.dof} degrees of freedom "
                f"(chi2/dof {self.chi_square / max(self.dof, 1):.3f}, {self.sigmas:+.1f} sigma, "
                f"p = {self.p_value:.2g}")
        if self.chi_square < self.dof:
            line += f", lower tail {self.p_below:.2g}"
        if self.failing:
            worst = self.failing[0]
            line += (f"; {len(self.failing)} of {self.windows_tested} windows fail at "
                     f"{self.alpha:g}/{self.windows_tested}, worst {worst.sensor}."
                     f"{worst.channel} {worst.window} with {worst.chi_square:.1f} on "
                     f"{worst.samples} samples (p = {window_p_value(worst):.2g})")
        return line + ")"

    def as_dict(self) -> dict:
        return {"chi_square": self.chi_square, "dof": self.dof, "p_value": self.p_value,
                "p_below": self.p_below, "alpha": self.alpha, "passes": self.passes,
                "above": self.above, "below": self.below,
                "windows_tested": self.windows_tested,
                "failing_windows": [{"sensor": w.sensor, "channel": w.channel,
                                     "window": w.window, "chi_square": w.chi_square,
                                     "samples": w.samples, "p_value": window_p_value(w)}
                                    for w in self.failing]}


def noise_test(fit: Fit, statistics: Sequence[WindowStatistic], alpha: float) -> NoiseTest:
    """The noise test of `fit` (see the module docstring), from its window statistics."""
    tested = [w for w in statistics if w.samples >= MIN_TESTED_SAMPLES]
    m = max(len(tested), 1)
    failing = sorted((w for w in tested if window_p_value(w) < alpha / m),
                     key=window_p_value)
    p = float(chi2_law.sf(fit.chi_square, fit.dof)) if fit.dof > 0 else 1.0
    return NoiseTest(fit.chi_square, fit.dof, p, alpha, len(tested), failing)
