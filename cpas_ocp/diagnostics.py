"""Where the model fits worst: residual statistics per sensor and per time window."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .estimation import Fit, SensorResidual


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
