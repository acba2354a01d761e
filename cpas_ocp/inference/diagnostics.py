"""Where the model fits worst: residual statistics per sensor, per time window and per
phase window (deployment, inflation, steady flight of each canopy)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_law
from scipy.stats import norm

from cpas_ocp.estimation.estimator import Fit, SensorResidual
from cpas_ocp.inference.phase_windows import OUTSIDE, PhaseWindow, window_index, windows_for_sensor


@dataclass(frozen=True)
class Window:
    """A time window of one sensor channel and its normalised residual RMS."""

    sensor: str
    channel: str
    t0: float
    t1: float
    normalised_rms: float
    samples: int


def sensor_summary(fit: Fit) -> dict[str, dict]:
    """Per sensor: RMS per channel (SI), normalised RMS over all its channels, sample count."""
    out: dict[str, dict] = {}
    for r in fit.residuals:
        entry = out.setdefault(r.sensor, {"rms": {}, "chi_square": 0.0, "samples": 0})
        entry["rms"][r.channel] = float(np.sqrt(np.mean((r.measured - r.model) ** 2)))
        entry["chi_square"] += float(np.sum(r.normalised**2))
        entry["samples"] += int(r.t.size)
    for entry in out.values():
        entry["normalised_rms"] = float(np.sqrt(entry["chi_square"] / entry["samples"]))
    return out


# The fewest samples a window of `worst_windows` holds: the normalised RMS of fewer is too
# noisy to rank (with 10 samples of pure noise its 99th percentile is 1.75; with 2, 2.6).
MIN_WINDOW_SAMPLES = 10


def worst_windows(fit: Fit, width: float = 0.5, top: int = 3) -> list[Window]:
    """The `top` non-overlapping windows with the largest normalised residual RMS, over every
    channel of the fit's sensors (not events, priors or a process's innovations).

    Each channel's windows are runs of consecutive samples, as many as it holds in `width`
    s at its median sampling interval but never fewer than MIN_WINDOW_SAMPLES: a 1 Hz GNSS
    channel gets windows of 10 s, a 100 Hz accelerometer of 0.5 s.  Windows of fixed
    duration held 0-1 samples of a slow channel, so its worst window was never ranked
    (a GNSS at normalised RMS 2.42 over the phase showed a worst window of 0.15).  The
    runs partition the channel into blocks of at least that many samples, plus the runs
    straddling each pair of neighbouring blocks: a channel's worst window is then at least
    its whole normalised RMS (the blocks' mean square is the channel's).  A channel with
    fewer samples than that is one window.
    """
    candidates: list[Window] = []
    for r in fit.residuals:
        if r.sensor not in fit.pseudo_sensors:
            candidates += _windows(r, width)
    candidates.sort(key=lambda w: w.normalised_rms, reverse=True)
    chosen: list[Window] = []
    for w in candidates:
        if all(w.sensor != c.sensor or w.t1 <= c.t0 or w.t0 >= c.t1 for c in chosen):
            chosen.append(w)
        if len(chosen) == top:
            break
    return chosen


def window_samples(t: np.ndarray, width: float) -> int:
    """Samples in a window of `width` s of a channel sampled at times `t` (s), at its median
    interval, and at least MIN_WINDOW_SAMPLES."""
    steps = np.diff(t)
    steps = steps[steps > 0]
    per_width = int(width / np.median(steps)) if steps.size else 0
    return max(MIN_WINDOW_SAMPLES, per_width)


def _windows(r: SensorResidual, width: float) -> list[Window]:
    """The windows of one channel (`worst_windows`): blocks of consecutive samples and the
    runs straddling neighbouring blocks; t0, t1 are their first and last samples' times."""
    order = np.argsort(r.t, kind="stable")
    t, z2 = np.asarray(r.t)[order], (np.asarray(r.normalised) ** 2)[order]
    if t.size == 0:
        return []
    n = window_samples(t, width)
    blocks = np.array_split(np.arange(t.size), max(1, t.size // n))
    runs = list(blocks)
    runs += [np.concatenate([a[a.size // 2:], b[:b.size // 2]])
             for a, b in itertools.pairwise(blocks)]
    return [Window(r.sensor, r.channel, float(t[i[0]]), float(t[i[-1]]),
                   float(np.sqrt(z2[i].mean())), int(i.size)) for i in runs]


@dataclass(frozen=True)
class WindowStatistic:
    """The residuals of one sensor channel in one phase window.

    rms: root mean square of measured minus model (SI, the channel's unit);
    normalised_rms: that of (measured - model) / sigma (1 for a model that
    explains the data to the noise); chi_square: the window's sum of squared
    normalised residuals; fraction: its share of the fit's total chi-square.
    t0, t1 (s): the first and last of the channel's samples counted in the
    window.  Not the window's own bounds: windows of different canopies overlap
    (an earlier canopy's steady window runs to the end of the phase), and a
    sample counts in only one of them.
    """

    sensor: str
    channel: str
    window: str
    t0: float
    t1: float
    samples: int
    rms: float
    normalised_rms: float
    chi_square: float
    fraction: float

    @property
    def excess(self) -> float:
        """chi^2 - n: what the window holds beyond the noise (expected 0 +- sqrt(2 n))."""
        return self.chi_square - self.samples


def window_statistics(fit: Fit, windows: Sequence[PhaseWindow]) -> list[WindowStatistic]:
    """Residual statistics of every sensor channel in every phase window it has samples in.

    Each sample counts in exactly one window (`phase_windows.window_index`; load
    cells see their own canopy's windows, vehicle sensors every canopy's), and
    samples outside every window are reported under OUTSIDE, so that a channel's
    window chi-squares add up to its total.  Observed event times are left out.
    """
    total = fit.chi_square
    out: list[WindowStatistic] = []
    for r in fit.residuals:
        if r.sensor in fit.pseudo_sensors or r.t.size == 0:
            continue
        applicable = windows_for_sensor(fit.test, r.sensor, windows)
        index = window_index(r.t, applicable)
        z2 = r.normalised**2
        d2 = (r.measured - r.model) ** 2
        for i in [*range(len(applicable)), -1]:
            sel = index == i
            if not sel.any():
                continue
            chi2 = float(np.sum(z2[sel]))
            out.append(WindowStatistic(
                r.sensor, r.channel, applicable[i].name if i >= 0 else OUTSIDE,
                float(r.t[sel][0]), float(r.t[sel][-1]),
                int(sel.sum()), float(np.sqrt(np.mean(d2[sel]))),
                float(np.sqrt(np.mean(z2[sel]))), chi2, chi2 / total if total > 0 else 0.0))
    return out


def worst_place(fit: Fit, windows: Sequence[PhaseWindow]) -> str:
    """One line naming the sensor channel and phase window where the model fails most beyond
    the noise: the largest chi-square excess chi^2 - n."""
    return worst_of(window_statistics(fit, windows))


# Fewest samples of a window that can be the worst fit: in fewer, a misfit cannot be told
# from one outlier (a one-sample "deployment" window read as the worst place).
MIN_RANKED_SAMPLES = 5


def worst_window(stats: Sequence[WindowStatistic]) -> WindowStatistic | None:
    """The window with the largest chi-square excess among those with at least
    MIN_RANKED_SAMPLES samples (among all where none has); None without windows."""
    ranked = [s for s in stats if s.samples >= MIN_RANKED_SAMPLES] or list(stats)
    return max(ranked, key=lambda s: s.excess) if ranked else None


def worst_of(stats: Sequence[WindowStatistic]) -> str:
    """The `worst_place` line from statistics already computed."""
    w = worst_window(stats)
    if w is None:
        return "no sensor samples to compare with the model"
    return (f"{w.sensor} {w.channel}, {w.window} ({w.t0:.2f}-{w.t1:.2f} s): chi-square "
            f"{w.chi_square:.1f} on {w.samples} samples (excess {w.excess:+.1f}), normalised "
            f"RMS {w.normalised_rms:.2f}, {100 * w.fraction:.1f} % of the total chi-square")


def excess_removed(before: Sequence[WindowStatistic], after: Sequence[WindowStatistic],
                   sigmas: float = 3.0
                   ) -> list[tuple[WindowStatistic, WindowStatistic, float]]:
    """For each window of `before` whose chi-square excess departs from the noise (more than
    `sigmas` times its spread sqrt(2 n)): that window in `after` (the same windows, another
    fit) and the share of the excess it no longer holds (1 where it came down to the
    noise, 0 where nothing changed, negative where it grew).  Worst window first."""
    later = {(w.sensor, w.channel, w.window): w for w in after}
    out = []
    for w in sorted(before, key=lambda w: w.excess, reverse=True):
        if not departs(w, sigmas):
            continue
        now = later.get((w.sensor, w.channel, w.window))
        if now is not None:
            out.append((w, now, (w.excess - now.excess) / w.excess))
    return out


# Fewest samples of a window whose chi-square is tested against the noise.  A window of a
# handful of samples (a deployment instant, a stage that lasts two GPS fixes) holds one or
# two residuals: its test is a test of one outlier, and among thousands of samples a 4
# sigma one is expected (p = 0.3 over 5,720).  Such windows neither fail a verdict nor make
# an effect a stand-in; they still count in the total chi-square.
MIN_TESTED_SAMPLES = 10


def window_p_value(w: WindowStatistic) -> float:
    """The chi-square tail probability of a window's residuals under the noise: its
    chi-square on as many degrees of freedom as it has samples (exact, where the normal
    approximation (chi^2 - n) / sqrt(2 n) makes one 4-sigma sample a 10-sigma window)."""
    return float(chi2_law.sf(w.chi_square, w.samples)) if w.samples else 1.0


def departs(w: WindowStatistic, sigmas: float) -> bool:
    """Whether a window of at least MIN_TESTED_SAMPLES samples departs from the noise: the
    tail probability of its chi-square (`window_p_value`) is below the normal tail at
    `sigmas` (the level a family-wise test over the windows sets)."""
    return w.samples >= MIN_TESTED_SAMPLES and window_p_value(w) < float(norm.sf(sigmas))


def explained_share(chi2_before: float, dof_before: int, chi2_after: float) -> float:
    """The share of the excess chi-square (chi^2 - dof, what the noise would not give) a
    model change removes: 1 brings the fit to the noise on average."""
    excess = chi2_before - dof_before
    return (chi2_before - chi2_after) / excess if excess > 0 else float("nan")
