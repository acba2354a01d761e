"""Where and how the residuals depart from noise: per sensor channel and phase window.

Each sensor channel's normalised residual is cut by phase window (deployment,
inflation, steady flight of each canopy: `phase_windows`) into contiguous
runs of samples, and every run of at least MIN_SAMPLES samples is tested:

* whiteness (`residual_tests.ljung_box`): an unmodelled transient or drift;
* one hidden oscillation (`residual_tests.periodicity`, at the run's median
  sampling rate): riser elasticity, canopy breathing, a structural mode;
* a time lag (`residual_tests.lag`): a sensor that trails (or leads) the model;
* correlation with each candidate signature of missing physics
  (`signatures.signature_correlations`): dynamic pressure, acceleration,
  drag-area rate, time since an event...

A channel most of whose samples lie in runs too short to test (GPS at 10 Hz
against sub-second inflation windows) is also tested as a whole, under the
window name WHOLE_PHASE.  A run whose residual is exactly constant (noise-free
data) has nothing to test and is skipped.

Many tests are made, so each p-value is judged by Holm's step-down
correction over all of them: the smallest of m p-values against alpha / m,
the next against alpha / (m - 1), ... until one fails.  The chance that
white-noise residuals give any significant finding is then at most alpha,
whatever the dependence between the tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from cpas_ocp.discrepancy.residual_tests import lag, ljung_box, periodicity
from cpas_ocp.discrepancy.signatures import (
    Correlation,
    Signature,
    signature_correlations,
    signatures,
)
from cpas_ocp.estimation.estimator import Fit, SensorResidual
from cpas_ocp.inference.phase_windows import OUTSIDE, PhaseWindow, window_index, windows_for_sensor

# Fewest samples in a run for the tests to mean something (Ljung-Box uses n / 5 lags).
MIN_SAMPLES = 20
# Window name of a channel tested as a whole.
WHOLE_PHASE = "whole phase"
# A channel is tested as a whole when windowed runs hold less than this share of it.
MIN_TESTED_FRACTION = 0.5
# A gap longer than this many median sampling intervals ends a run.
GAP_INTERVALS = 1.5
# Signature correlations a finding's text names.
TOP_CORRELATIONS = 3
# Test labels of a finding other than its signature correlations.
LJUNG_BOX, PERIODICITY, LAG = "Ljung-Box", "periodicity", "lag"
# A sensor's lag (its filter or its report's delay) is positive, below a second, and a
# small part of the window it is seen in (s; share).  A residual that follows the model's
# rate with any other "lag" (a GPS reporting 2.6 s before the event, an accelerometer
# 5.5 s behind it over a two-minute drogue descent) is a slow misfit in step with the
# rate, not a sensor's delay, and is described as such.
MAX_SENSOR_LAG_S = 1.0
MAX_LAG_WINDOW_SHARE = 0.1


@dataclass
class Finding:
    """The tests of one sensor channel in one window (t0 to t1, s).

    ljung_box_p: whiteness; frequency_hz and periodicity_p: the periodogram's
    strongest line and its Fisher g p-value; lag_s, lag_se, lag_p: the sensor
    lag (s, positive when the measurement trails the model), its standard error
    and p-value (None where the model output does not change); correlations:
    every signature correlation, strongest first.  `rejected` lists the tests (by
    label or signature name) whose p-value passes the multiple-test correction,
    `p_adjusted` the smallest Holm-adjusted p-value of the finding's tests, and
    `significant` whether any passed.
    """

    sensor: str
    channel: str
    window: str
    t0: float
    t1: float
    samples: int
    normalised_rms: float
    ljung_box_p: float
    frequency_hz: float
    periodicity_p: float
    lag_s: float | None
    lag_se: float | None
    lag_p: float | None
    correlations: list[Correlation] = field(default_factory=list)
    significant: bool = False
    p_adjusted: float = 1.0
    rejected: tuple[str, ...] = ()

    def __str__(self) -> str:
        """One line: where, and what the residual there shows."""
        head = (f"{self.sensor} {self.channel}, {self.window} ({self.t0:.2f}-{self.t1:.2f} s, "
                f"{self.samples} samples, normalised RMS {self.normalised_rms:.2f})")
        parts = []
        if LJUNG_BOX in self.rejected:
            parts.append(f"not white (Ljung-Box p {_p(self.ljung_box_p)})")
        if PERIODICITY in self.rejected:
            parts.append(f"{self.frequency_hz:.2f} Hz line (p {_p(self.periodicity_p)})")
        if LAG in self.rejected and self.lag_s is not None and self.lag_se is not None:
            parts.append(f"{lag_text(self, 1)} (p {_p(self.lag_p or 0.0)})")
        parts += [f"correlates with {c.signature} r={c.r:+.2f} (p {_p(c.p_value)})"
                  for c in self.shown_correlations]
        if not parts:
            return (f"{head}: consistent with white noise (smallest corrected p "
                    f"{_p(self.p_adjusted)})")
        return f"{head}: " + "; ".join(parts)


    @property
    def shown_correlations(self) -> list[Correlation]:
        """The TOP_CORRELATIONS strongest of the significant signature correlations: what a
        line of text names (monotonic signatures, such as the time since an event and the
        altitude, correlate alike with a slow drift, and naming all says no more)."""
        return [c for c in self.correlations if c.signature in self.rejected][:TOP_CORRELATIONS]


def plausible_lag(f: Finding) -> bool:
    """Whether the finding's lag estimate could be a sensor's: positive, at most
    MAX_SENSOR_LAG_S, and at most MAX_LAG_WINDOW_SHARE of its window."""
    return f.lag_s is not None and 0.0 < f.lag_s <= min(
        MAX_SENSOR_LAG_S, MAX_LAG_WINDOW_SHARE * (f.t1 - f.t0))


def lag_text(f: Finding, decimals: int) -> str:
    """The lag test's rejection in words (ms to `decimals`): a lag where it could be a
    sensor's (`plausible_lag`), else a residual in step with the model's rate."""
    value = f"{1e3 * (f.lag_s or 0.0):+.{decimals}f} ± {1e3 * (f.lag_se or 0.0):.{decimals}f} ms"
    if plausible_lag(f):
        return f"a lag of {value}"
    why = ("negative: the sensor would report before the event" if (f.lag_s or 0.0) <= 0.0
           else f"beyond {MAX_SENSOR_LAG_S:g} s or a tenth of the window")
    return (f"follows the model's rate of change, not as a sensor lag (as one it would be "
            f"{value}, {why})")


def diagnose_residuals(fit: Fit, windows: Sequence[PhaseWindow], alpha: float = 0.01,
                       candidates: Sequence[Signature] | None = None) -> list[Finding]:
    """Test every sensor channel in every phase window with enough samples; Holm-correct
    over all tests at level `alpha`; significant findings first, by corrected p-value,
    then the rest by normalised RMS.

    `candidates`: the signatures to correlate with (default: `signatures(fit)`).
    """
    sigs = signatures(fit) if candidates is None else list(candidates)
    findings: list[Finding] = []
    tests: list[tuple[int, str, float]] = []
    for r in fit.residuals:
        if r.sensor in fit.pseudo_sensors or r.t.size < MIN_SAMPLES:
            continue
        applicable = windows_for_sensor(fit.test, r.sensor, windows)
        index = window_index(r.t, applicable)
        tested = 0
        for i in [*range(len(applicable)), -1]:
            name = applicable[i].name if i >= 0 else OUTSIDE
            for run in _runs(r.t, index == i):
                if run.size >= MIN_SAMPLES and np.ptp(r.normalised[run]) > 0:
                    finding, p_values = _examine(_subset(r, run), name, sigs)
                    tests += [(len(findings), label, p) for label, p in p_values]
                    findings.append(finding)
                    tested += run.size
        if tested < MIN_TESTED_FRACTION * r.t.size and np.ptp(r.normalised) > 0:
            finding, p_values = _examine(r, WHOLE_PHASE, sigs)
            tests += [(len(findings), label, p) for label, p in p_values]
            findings.append(finding)
    _holm(findings, tests, alpha)
    return sorted(findings, key=lambda f: (not f.significant, f.p_adjusted,
                                           -f.normalised_rms))


def signature_text(findings: Sequence[Finding], top: int = 3) -> str:
    """A few lines describing the residual signature of the most significant findings: where
    the residual is strongest, at what frequency, with what lag, following which signature
    (and the physics that signature points to)."""
    hits = [f for f in findings if f.significant][:top]
    if not hits:
        return (f"No residual signature beyond the noise: none of the {len(findings)} channel "
                "windows tested departs from white noise after the correction for multiple "
                "tests.")
    lines = [f"Residual signature ({sum(f.significant for f in findings)} of {len(findings)} "
             "channel windows depart from white noise):"]
    for k, f in enumerate(hits):
        where = (f"{'strongest' if k == 0 else 'then'} in {f.sensor} {f.channel}, window "
                 f"{f.window} ({f.t0:.2f}-{f.t1:.2f} s, normalised RMS {f.normalised_rms:.2f})")
        what = []
        if PERIODICITY in f.rejected:
            what.append(f"periodic at {f.frequency_hz:.2f} Hz")
        if LAG in f.rejected and f.lag_s is not None and f.lag_se is not None:
            what.append(lag_text(f, 0))
        what += [f"correlates with {c.signature} (r {c.r:+.2f}: {c.points_to})"
                 for c in f.shown_correlations]
        if LJUNG_BOX in f.rejected and not what:
            what.append("serially correlated, with no single frequency, lag or signature")
        lines.append(f"- {where}: {'; '.join(what) or 'not white'}")
    return "\n".join(lines)


def _examine(r: SensorResidual, window: str,
             sigs: Sequence[Signature]) -> tuple[Finding, list[tuple[str, float]]]:
    """Every test on one contiguous run of one channel; the finding and its (label, p)."""
    e = r.normalised
    rate = 1.0 / float(np.median(np.diff(r.t)))
    lb = ljung_box(e)
    per = periodicity(e, rate)
    try:
        lg = lag(e, r.model, r.sigma, r.t)
    except ValueError:  # the model output is flat: no lag can be seen
        lg = None
    t0, t1 = float(r.t[0]), float(r.t[-1])
    corr = signature_correlations(r, sigs, t0, t1)
    finding = Finding(r.sensor, r.channel, window, t0, t1, int(r.t.size),
                      float(np.sqrt(np.mean(e**2))), lb.p_value, float(per.value or 0.0),
                      per.p_value, None if lg is None else lg.value,
                      None if lg is None else lg.std, None if lg is None else lg.p_value,
                      corr)
    p_values = [(LJUNG_BOX, lb.p_value), (PERIODICITY, per.p_value)]
    if lg is not None:
        p_values.append((LAG, lg.p_value))
    p_values += [(c.signature, c.p_value) for c in corr]
    return finding, p_values


def _holm(findings: list[Finding], tests: list[tuple[int, str, float]], alpha: float) -> None:
    """Holm's step-down correction over all tests: sets each finding's `rejected`,
    `significant` and `p_adjusted` (the adjusted p-value of its best test)."""
    m = len(tests)
    order = sorted(range(m), key=lambda k: tests[k][2])
    running = 0.0
    stopped = False
    rejected: dict[int, list[str]] = {}
    best = [1.0] * len(findings)
    for rank, k in enumerate(order):
        i, label, p = tests[k]
        running = max(running, min(1.0, (m - rank) * p))
        best[i] = min(best[i], running)
        if not stopped and p <= alpha / (m - rank):
            rejected.setdefault(i, []).append(label)
        else:
            stopped = True
    for i, f in enumerate(findings):
        f.rejected = tuple(rejected.get(i, ()))
        f.significant = bool(f.rejected)
        f.p_adjusted = best[i]


def _runs(t: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """Indices of the contiguous runs of selected samples (a gap of more than GAP_INTERVALS
    median sampling intervals, or an unselected sample, ends a run)."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    breaks = np.flatnonzero((np.diff(idx) > 1) | (np.diff(t[idx]) > GAP_INTERVALS * dt)) + 1
    return np.split(idx, breaks)


def _subset(r: SensorResidual, idx: np.ndarray) -> SensorResidual:
    return replace(r, t=r.t[idx], measured=r.measured[idx], model=r.model[idx],
                   sigma=r.sigma[idx])


def _p(p: float) -> str:
    """A p-value for reading: three decimals, or one significant digit when small."""
    return f"{p:.3f}" if p >= 1e-3 else f"{p:.0e}"
