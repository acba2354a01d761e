"""Residual that two independent sensors of the same quantity share: the vehicle, not a sensor.

A barometric altimeter and a GPS receiver measure the vehicle's altitude
with errors that have nothing in common (pressure-port errors and lag; the
satellite geometry).  Where their residuals against the model rise and fall
together, the vehicle's own altitude departs from the model: the missing
effect is physics (the descent rate varies in a way the model lacks) and no
sensor model (bias, lag, scale) can remove it.  Where one sensor's residual
wanders alone, that sensor's model is at fault.

Each altitude channel's residual (m) is averaged over consecutive blocks of
`block_s` seconds, which keeps the slow wander and drops the sensor noise,
and the two channels' block means are correlated over each stretch of
descent between consecutive events.  The block means of a slow wander are
still autocorrelated, so the correlation's p-value counts
n (1 - r1 r2) / (1 + r1 r2) effective samples (Bretherton et al., 1999;
r1, r2 the lag-one autocorrelations: `signatures.effective_samples`).
The stretches hold independent data, so their one-sided p-values combine by
Fisher's method into one test of "the two sensors share no residual".
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.stats import combine_pvalues

from cpas_ocp.discrepancy.signatures import (
    correlation_p_value,
    effective_samples,
    lag1_autocorrelation,
)
from cpas_ocp.estimation.estimator import Fit, SensorResidual

BLOCK_S = 5.0  # the residuals are averaged over blocks this long (s)
MIN_STRETCH_S = 30.0  # a stretch between events shorter than this is not tested (s)
MIN_BLOCKS = 6  # fewest blocks in a tested stretch
# The channels that measure the vehicle's altitude, by sensor kind.
ALTITUDE_CHANNELS = {"baro": "altitude", "gps_altitude": "up", "gps": "up"}


@dataclass(frozen=True)
class CommonResidual:
    """Two altitude channels' block-mean residuals over [t0, t1] (s): their correlation r,
    its one-sided p-value (r > 0) on `effective` samples, and each one's RMS (m)."""

    channels: tuple[str, str]
    t0: float
    t1: float
    blocks: int
    r: float
    p_value: float
    effective: float
    rms: tuple[float, float]

    def __str__(self) -> str:
        return (f"{self.channels[0]} and {self.channels[1]}, {self.t0:.1f}-{self.t1:.1f} s: "
                f"{BLOCK_S:g} s means correlate r = {self.r:+.2f} over {self.blocks} blocks "
                f"(one-sided p = {self.p_value:.2g} on {self.effective:.1f} effective samples; "
                f"RMS {self.rms[0]:.1f} m and {self.rms[1]:.1f} m)")


def altitude_residuals(fit: Fit) -> list[SensorResidual]:
    """The fit's residuals of channels that measure the vehicle's altitude."""
    kinds = {s.name: s.kind for s in fit.test.sensors}
    return [r for r in fit.residuals
            if ALTITUDE_CHANNELS.get(kinds.get(r.sensor, "")) == r.channel]


def stretches(fit: Fit) -> list[tuple[float, float]]:
    """The phase cut at its events, keeping the stretches at least MIN_STRETCH_S long (s)."""
    test = fit.test
    cuts = sorted({e.time for e in test.events if test.t_start < e.time < test.t_end})
    edges = [test.t_start, *cuts, test.t_end]
    return [(a, b) for a, b in itertools.pairwise(edges) if b - a >= MIN_STRETCH_S]


def common_residuals(fit: Fit, block_s: float = BLOCK_S) -> list[CommonResidual]:
    """Every pair of the fit's altitude channels, over every stretch between events."""
    out = []
    for a, b in itertools.combinations(altitude_residuals(fit), 2):
        out += shared_residuals(a, b, stretches(fit), block_s)
    return out


def shared_residuals(a: SensorResidual, b: SensorResidual,
                     spans: list[tuple[float, float]], block_s: float = BLOCK_S
                     ) -> list[CommonResidual]:
    """Block-mean residuals of channels `a` and `b` correlated over each span (s)."""
    out = []
    for t0, t1 in spans:
        starts = np.arange(t0, t1 - block_s + 1e-9, block_s)
        ma, mb = (_block_means(r, starts, block_s) for r in (a, b))
        ok = np.isfinite(ma) & np.isfinite(mb)
        if ok.sum() < MIN_BLOCKS:
            continue
        ma, mb = ma[ok], mb[ok]
        r = float(np.corrcoef(ma, mb)[0, 1])
        n_eff = effective_samples(int(ok.sum()), lag1_autocorrelation(ma),
                                  lag1_autocorrelation(mb))
        p = 0.5 * correlation_p_value(r, n_eff) if r > 0 else 1.0
        out.append(CommonResidual((_label(a), _label(b)), t0, t1, int(ok.sum()), r, p,
                                  n_eff, (_rms(ma), _rms(mb))))
    return out


def combined_p_value(found: list[CommonResidual]) -> float:
    """Fisher's combination of the stretches' one-sided p-values (1 without any)."""
    if not found:
        return 1.0
    return float(combine_pvalues([c.p_value for c in found], method="fisher").pvalue)


def _block_means(r: SensorResidual, starts: np.ndarray, block_s: float) -> np.ndarray:
    """Mean residual (m) of the samples in each block [start, start + block_s); NaN if empty."""
    e = r.measured - r.model
    c = np.concatenate([[0.0], np.cumsum(e)])
    lo = np.searchsorted(r.t, starts, side="left")
    hi = np.searchsorted(r.t, starts + block_s, side="left")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(hi > lo, (c[hi] - c[lo]) / np.maximum(hi - lo, 1), np.nan)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def _label(r: SensorResidual) -> str:
    return f"{r.sensor} {r.channel}"
