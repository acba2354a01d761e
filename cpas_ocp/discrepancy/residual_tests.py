"""Statistical tests on one channel's normalised residuals: is what is left noise?

A model that explains the data leaves normalised residuals e_i = (y_i - h_i)/sigma_i
that are white, unit-variance noise.  What a missing effect leaves behind
has a signature these tests name:

* `ljung_box`: serial correlation (a slow drift, an unmodelled transient) —
  Q = n (n + 2) sum_{k=1}^{h} rho_k^2 / (n - k), chi-square with h degrees of
  freedom under whiteness (Ljung and Box 1978);
* `periodicity`: a hidden oscillation (riser elasticity, canopy breathing) —
  the periodogram's largest ordinate against their sum, Fisher's g test,
  P(g > x) = sum_j (-1)^(j-1) C(m, j) (1 - j x)^(m-1) over j < 1/x (Fisher
  1929), with the frequency of that ordinate (Hz);
* `lag`: a sensor time lag tau, which leaves e ~ -tau dh/dt / sigma to first
  order; tau is the least-squares slope of the residual on the model's own
  rate, with its standard error (s), so that tau / se is a z statistic.

Every function takes uniformly sampled series (a sensor's samples in the
fit window); the caller chooses the channel and window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import periodogram
from scipy.special import comb
from scipy.stats import chi2


@dataclass(frozen=True)
class TestResult:
    """A statistic, its p-value under "the residual is white noise", and what it found."""

    statistic: float
    p_value: float
    value: float | None = None  # frequency (Hz) or lag (s) where the test names one
    std: float | None = None  # standard error of `value` where it has one


def default_lags(n: int) -> int:
    """min(20, n / 5) lags: the usual choice for the Ljung-Box test."""
    return max(1, min(20, n // 5))


def ljung_box(e: np.ndarray, lags: int | None = None) -> TestResult:
    """Ljung-Box portmanteau test of whiteness on the first `lags` autocorrelations."""
    e = np.asarray(e, dtype=float) - np.mean(e)
    n = e.size
    h = default_lags(n) if lags is None else lags
    if n < h + 2:
        raise ValueError(f"{n} samples are too few for {h} lags")
    denom = float(e @ e)
    rho = np.array([float(e[k:] @ e[:-k]) / denom for k in range(1, h + 1)])
    q = n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, h + 1))))
    return TestResult(q, float(chi2.sf(q, h)))


def periodicity(e: np.ndarray, rate_hz: float) -> TestResult:
    """Fisher's g test for one hidden sinusoid; `value` is its frequency (Hz).

    The zero frequency and (for even n) the Nyquist ordinate are left out, so
    the m remaining ordinates are exchangeable chi-square_2 under whiteness.
    """
    f, p = periodogram(np.asarray(e, dtype=float) - np.mean(e), fs=rate_hz, detrend=False)
    keep = slice(1, -1) if np.asarray(e).size % 2 == 0 else slice(1, None)
    f, p = f[keep], p[keep]
    m = p.size
    if m < 2:
        raise ValueError("too few samples for a periodogram")
    g = float(p.max() / p.sum())
    jmax = int(np.floor(1.0 / g))
    j = np.arange(1, min(jmax, m) + 1)
    tail = float(np.sum((-1.0) ** (j - 1) * comb(m, j) * (1.0 - j * g) ** (m - 1)))
    return TestResult(g, float(np.clip(tail, 0.0, 1.0)), float(f[np.argmax(p)]))


def lag(e: np.ndarray, model: np.ndarray, sigma: np.ndarray, t: np.ndarray) -> TestResult:
    """Sensor lag tau (s) from e ~ -tau (dh/dt) / sigma, with its standard error.

    `model` is the fitted output h at the sample times `t` (s), `sigma` the
    samples' sigmas; the statistic is tau / se, the p-value two-sided.  A
    positive tau means the measurement trails the model.
    """
    model = np.asarray(model, dtype=float)
    t = np.asarray(t, dtype=float)
    rate = np.gradient(model, t)
    typical = max(float(np.max(np.abs(model))), 1e-300) / max(float(t[-1] - t[0]), 1e-300)
    if float(np.max(np.abs(rate))) <= 1e-9 * typical:
        raise ValueError("the model output does not change: no lag is observable")
    x = -rate / np.asarray(sigma, dtype=float)
    sxx = float(x @ x)
    tau = float(x @ np.asarray(e, dtype=float)) / sxx
    se = 1.0 / np.sqrt(sxx)
    z = tau / se
    return TestResult(z, float(chi2.sf(z * z, 1)), tau, float(se))  # two-sided normal p
