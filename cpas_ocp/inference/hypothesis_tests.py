"""Likelihood-ratio and score-test laws shared by what-if constraints, score tests and model
comparison.

A statistic T (a chi-square difference, in units where each residual has unit
variance) tests k_eq restrictions that may lie on either side and k_in that
hold a parameter on a bound (a one-sided alternative: an added-mass factor
cannot be negative).  Under the null T follows chi-bar-squared,

    P(T > x) = sum_j w_j P(chi^2_{k_eq + j} > x),  j = 0 .. k_in,

with weights w_j the probability that j of the one-sided restrictions are
active.  The binomial weights C(k_in, j) / 2^k_in used here are exact for
uncorrelated one-sided estimates and a fair approximation otherwise
(Silvapulle and Sen, Constrained Statistical Inference, Ch. 3).
"""

from __future__ import annotations

from math import comb

import numpy as np
from scipy.optimize import lsq_linear
from scipy.stats import chi2


def chi_bar_square_sf(x: float, k_eq: int, k_in: int = 0) -> float:
    """P(T > x) for k_eq two-sided and k_in one-sided restrictions (1 when none)."""
    p = 0.0
    for j in range(k_in + 1):
        dof = k_eq + j
        tail = (1.0 if x <= 0.0 else 0.0) if dof == 0 else float(chi2.sf(x, dof))
        p += comb(k_in, j) / 2.0**k_in * tail
    return p


def cone_statistic(theta: np.ndarray, covariance: np.ndarray, lower: np.ndarray,
                   upper: np.ndarray) -> float:
    """The chi-square decrease a linearised estimate `theta` (its `covariance`) offers within
    the cone of alternatives ``lower <= t <= upper`` (0 or +-inf per coordinate):

        T = theta' W theta - min over the cone of (t - theta)' W (t - theta),  W = C^-1.

    With an unbounded cone T is the Wald/score form theta' W theta; a coordinate
    whose alternative lies on one side only (a bound at the null) loses what the
    estimate offers on the other.  Directions the covariance does not determine
    carry no weight (pseudo-inverse).
    """
    W = np.linalg.pinv(0.5 * (covariance + covariance.T))
    full = float(theta @ W @ theta)
    if np.all(np.isinf(lower)) and np.all(np.isinf(upper)):
        return full
    # Nearest point of the cone in W's metric: |L'(t - theta)| with W = L L'.
    eigval, eigvec = np.linalg.eigh(W)
    L = eigvec * np.sqrt(np.clip(eigval, 0.0, None))
    nearest = lsq_linear(L.T, L.T @ theta, bounds=(lower, upper), method="bvls").x
    d = nearest - theta
    return max(full - float(d @ W @ d), 0.0)
