"""The residuals' own curvature, learnt from the steps a descent takes (Dennis, Gay and Welsch).

Chi-square's Hessian in the free coordinates w (first-node states, free
parameters, captured speeds; the shooting states follow them along the gaps)
is 2 (G'G + S), G = dr/dw the reduced Jacobian and S = sum_i r_i d2r_i/dw2.
Gauss-Newton keeps G'G and drops S, which is small only where the residuals
are: on a misspecified model or a real log they are not, and S also carries
the curvature of the trajectory itself, which bends a valley of chi-square
that Gauss-Newton steps cross and recross.  On the Prometheus TeleMetrum log,
with the main's fill exponent held at 2 and the air's motion estimated, each
Gauss-Newton step of the feasible descent rose to chi-square 5,347-5,370 from
5,324 and its halvings gained 0.001-0.02: 15 steps did not cross the valley.

NL2SOL's answer (Dennis, Gay & Welsch, ACM TOMS 7, 1981) learns S from the
steps: after a step s, with the gradients g = G'r before and after, S is
given the least change (in the metric of the gradient change y = g+ - g)
that satisfies the structured secant condition S s = (G+ - G)' r+, which is
what S s is to first order.  S is first scaled down by min(1, |s'y#| / |s'Ss|)
(its sizing: a curvature learnt far away is not trusted near here).  The
update needs curvature along the step (y's > 0); a step without is skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class StructuredSecant:
    """The learnt second-order part S of the reduced Hessian (units of G'G: chi-square / 2
    per scaled unit squared) over the decision vector's `columns` (the free coordinates
    w, set by the first point observed), with the last point's w, reduced Jacobian G and
    weighted residuals r."""

    columns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    S: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    _last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def observe(self, z: np.ndarray, columns: np.ndarray, G: np.ndarray, r: np.ndarray
                ) -> None:
        """A new point `z` (scaled decision vector) with its reduced Jacobian `G` over the
        decision vector's `columns` and its weighted residuals `r`: S updated along the
        step from the last point (a point with other free columns starts afresh)."""
        if self._last is None or not np.array_equal(columns, self.columns):
            self.columns, self.S = columns, np.zeros((columns.size, columns.size))
            self._last = None
        w = z[columns]
        if self._last is not None:
            w0, G0, r0 = self._last
            self._update(w - w0, G.T @ r - G0.T @ r0, (G - G0).T @ r)
        self._last = (w, G, r)

    def _update(self, s: np.ndarray, y: np.ndarray, y_sharp: np.ndarray) -> None:
        """The sized Dennis-Gay-Welsch update along the step `s`, with the gradient change
        `y` and the structured target `y_sharp` = (G+ - G)' r+."""
        ys = float(y @ s)
        if not ys > 1e-12 * float(np.linalg.norm(y) * np.linalg.norm(s)):
            return  # no curvature along the step: nothing to learn from it
        sSs = float(s @ self.S @ s)
        if sSs != 0.0:
            self.S *= min(1.0, abs(float(s @ y_sharp)) / abs(sSs))
        v = y_sharp - self.S @ s
        self.S += (np.outer(v, y) + np.outer(y, v)) / ys - float(v @ s) * np.outer(y, y) / ys**2
