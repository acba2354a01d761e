"""Where the model fits worst: residual statistics per sensor, per time window and per
phase window (deployment, inflation, steady flight of each canopy)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpas_ocp.estimation.estimator import Fit, SensorResidual
from cpas_ocp.inference.phase_windows import OUTSIDE, PhaseWindow, window_index, windows_for_sensor


@dataclass(frozen=True)
class Window:
    """A time window of one sensor channel and its normalised residual RMS."""

    sensor: str
    channel: str
    t0: float
    t1: float
    normalized_rms: float
    samples: int


def sensor_summary(fit: Fit) -> dict[str, dict]:
    """Per sensor: RMS per channel (SI), normalised RMS over all its channels, sample count."""
    out: dict[str, dict] = {}
    for r in fit.residuals:
        entry = out.setdefault(r.sensor, {"rms": {}, "chi_square": 0.0, "samples": 0})
        entry["rms"][r.channel] = float(np.sqrt(np.mean((r.measured - r.model) ** 2)))
        entry["chi_square"] += float(np.sum(r.normalized**2))
        entry["samples"] += int(r.t.size)
    for entry in out.values():
        entry["normalized_rms"] = float(np.sqrt(entry["chi_square"] / entry["samples"]))
    return out


def worst_windows(fit: Fit, width: float = 0.5, top: int = 3) -> list[Window]:
    """The `top` non-overlapping windows of `width` s with the largest normalised residual RMS.

    Windows are scanned on a grid of half their width over every sensor channel.
    """
    candidates: list[Window] = []
    for r in fit.residuals:
        candidates += _windows(r, width)
    candidates.sort(key=lambda w: w.normalized_rms, reverse=True)
    chosen: list[Window] = []
    for w in candidates:
        if all(w.sensor != c.sensor or w.t1 <= c.t0 or w.t0 >= c.t1 for c in chosen):
            chosen.append(w)
        if len(chosen) == top:
            break
    return chosen


def _windows(r: SensorResidual, width: float) -> list[Window]:
    z2 = r.normalized**2
    out = []
    start = r.t[0]
    while start < r.t[-1]:
        sel = (r.t >= start) & (r.t < start + width)
        if sel.sum() >= 3:
            out.append(Window(r.sensor, r.channel, float(start), float(start + width),
                              float(np.sqrt(z2[sel].mean())), int(sel.sum())))
        start += width / 2
    return out


@dataclass(frozen=True)
class WindowStatistic:
    """The residuals of one sensor channel in one phase window.

    rms: root mean square of measured minus model (SI, the channel's unit);
    normalized_rms: that of (measured - model) / sigma (1 for a model that
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
    normalized_rms: float
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
        z2 = r.normalized**2
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
            f"RMS {w.normalized_rms:.2f}, {100 * w.fraction:.1f} % of the total chi-square")


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


def departs(w: WindowStatistic, sigmas: float) -> bool:
    """Whether a window's chi-square excess is more than `sigmas` times the spread the noise
    gives it, sqrt(2 n)."""
    return w.excess > sigmas * np.sqrt(2.0 * w.samples)


def explained_share(chi2_before: float, dof_before: int, chi2_after: float) -> float:
    """The share of the excess chi-square (chi^2 - dof, what the noise would not give) a
    model change removes: 1 brings the fit to the noise on average."""
    excess = chi2_before - dof_before
    return (chi2_before - chi2_after) / excess if excess > 0 else float("nan")
