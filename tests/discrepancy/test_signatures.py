"""Signatures of missing physics, and a residual's correlation with them.

Seeded synthetic residuals against synthetic signatures test the statistics:

* white noise plus 0.5 sigma times a (unit-variance) smooth signature gives
  r near 0.5 / sqrt(1.25) = 0.45; the residual is then itself serially
  correlated (lag-1 autocorrelation about 0.25 / 1.25 = 0.2), so of 400
  samples about n (1 - 0.2) / (1 + 0.2) = 270 count, t = r sqrt(268 / (1 - r^2))
  is near 8 and p near 1e-14: the signature comes first with p < 1e-8 (r two
  standard errors, 0.09, low still gives p near 1e-9);
* under white noise the p-values are uniform: over 100 series the count
  below 0.05 lies in the binomial(100, 0.05) 0.001-0.999 band;
* residuals with serial correlation of their own (AR(1), phi = 0.8) against
  a smooth signature: the effective sample size keeps the count in that band,
  where the naive n would flag about half of the series (variance of r
  inflated by (1 + phi) / (1 - phi) = 9).

The fbcp fit's own signatures check their construction.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from cpas_ocp.discrepancy.signatures import (
    Signature,
    correlation_p_value,
    signature_correlations,
    signatures,
)
from cpas_ocp.estimation.estimator import SensorResidual
from cpas_ocp.physics.parameters import param_name

RATE_HZ = 100.0
N = 400
SERIES = 100
T = np.arange(N) / RATE_HZ
BAND = binom.ppf([0.001, 0.999], SERIES, 0.05)


def _residual(e: np.ndarray) -> SensorResidual:
    """A channel whose normalised residual is `e` (model 0, sigma 1)."""
    return SensorResidual("imu", "load_factor", T, e, np.zeros_like(e), np.ones_like(e))


def _candidates() -> list[Signature]:
    """Three shapes a missing effect could leave: a transient bump (like dCdS/dt), a ramp
    after an event, a slow swing (like q over a stage)."""
    shapes = {
        "bump": np.exp(-(((T - 1.5) / 0.3) ** 2)),
        "ramp": np.maximum(T - 0.5, 0.0),
        "swing": np.sin(2 * np.pi * 0.3 * T + 1.0),
    }
    return [Signature(name, "1", name, T, values) for name, values in shapes.items()]


def _unit(x: np.ndarray) -> np.ndarray:
    return (x - x.mean()) / x.std()


@pytest.mark.parametrize("injected", ["bump", "ramp", "swing"])
def test_a_half_sigma_signature_comes_first_with_a_small_p(injected: str) -> None:
    cands = _candidates()
    shape = next(s.values for s in cands if s.name == injected)
    rng = np.random.default_rng(5)
    e = rng.standard_normal(N) + 0.5 * _unit(shape)
    found = signature_correlations(_residual(e), cands, T[0], T[-1])
    assert found[0].signature == injected
    assert found[0].r > 0
    assert found[0].p_value < 1e-8
    assert found[0].samples == N


def test_white_noise_gives_uniform_p_values() -> None:
    rng = np.random.default_rng(2024)
    cands = _candidates()
    flagged = dict.fromkeys((s.name for s in cands), 0)
    for _ in range(SERIES):
        for c in signature_correlations(_residual(rng.standard_normal(N)), cands, T[0], T[-1]):
            flagged[c.signature] += c.p_value < 0.05
    for name, count in flagged.items():
        assert BAND[0] <= count <= BAND[1], (name, count)


def test_serially_correlated_residuals_are_judged_on_their_effective_samples() -> None:
    rng = np.random.default_rng(77)
    phi = 0.8
    bump = _candidates()[:1]
    flagged = naive = 0
    for _ in range(SERIES):
        w = rng.standard_normal(N + 200) * np.sqrt(1 - phi**2)
        e = np.empty_like(w)
        e[0] = rng.standard_normal()
        for k in range(1, w.size):
            e[k] = phi * e[k - 1] + w[k]
        (c,) = signature_correlations(_residual(e[200:]), bump, T[0], T[-1])
        assert c.effective_samples < 0.3 * N
        flagged += c.p_value < 0.05
        naive += correlation_p_value(c.r, N) < 0.05
    assert BAND[0] <= flagged <= BAND[1], flagged
    assert naive > BAND[1], naive


def test_window_selection_and_flat_signatures() -> None:
    rng = np.random.default_rng(3)
    e = rng.standard_normal(N)
    flat = Signature("flat", "1", "nothing", T, np.full(N, 2.0))
    step = Signature("after", "s", "a transient", T, np.maximum(T - 3.0, 0.0))
    found = signature_correlations(_residual(e), [flat, step], 0.0, 2.0)
    assert found == []  # constant over [0, 2] s: left out
    found = signature_correlations(_residual(e), [flat, step], 2.5, 3.99)
    assert [c.signature for c in found] == ["after"]
    assert found[0].samples == int(np.sum((T >= 2.5) & (T <= 3.99)))
    assert signature_correlations(_residual(e), [step], 3.5, 3.515) == []  # two samples


def test_signatures_of_a_fit(problem_fit) -> None:
    fit, _, _ = problem_fit("fbcp", 1)
    sigs = {s.name: s for s in signatures(fit)}
    q = fit.quantities()
    for name in ("dynamic_pressure", "airspeed", "load_factor", "d(load_factor)/dt"):
        assert name in sigs
    assert not any(n.startswith("stretch") for n in sigs)  # rigid risers: no stretch
    for chute in ("fbcp1", "fbcp2"):
        rate = sigs[param_name("dCdS/dt", chute)].values
        cds = q[param_name("cds", chute)]
        # The numerical rate integrates back to the drag area's growth (to 0.1 %).
        grown = cds[-1] - cds[0]
        assert np.trapezoid(rate, fit.t) == pytest.approx(grown, rel=1e-3)
        # It peaks during the rise, between the stage's start and its over-inflation peak.
        t_peak = fit.t[np.argmax(rate)]
        start = fit.parameters[param_name("t_start", chute, "stage1")]
        assert start < t_peak < q[param_name("rise_end", chute, "stage1")][0]
        assert param_name("dT/dt", chute) in sigs
    for event in fit.test.events:
        since = sigs[f"time since {param_name(event.name, event.parachute)}"].values
        before = fit.t < event.time
        assert np.all(since[before] == 0.0)
        np.testing.assert_allclose(since[~before], fit.t[~before] - event.time)
