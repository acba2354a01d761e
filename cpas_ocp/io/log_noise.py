"""A log's noise and its dead stretches: the scatter of a series about its local trend, its
correlation length, independent blocks of a descent, the time a canopy has settled, and
readings a stuck or clipped channel repeated.  Units are the series' own (SI).
"""


from __future__ import annotations

from collections.abc import Callable
from itertools import pairwise

import numpy as np
import pandas as pd
from scipy.ndimage import maximum_filter1d
from scipy.signal import savgol_filter

from cpas_ocp.io.flight_events import (
    sample_interval,
    second_difference_sigma,
)

MIN_DESCENT_SAMPLES = 20  # least altimeter samples of a descent that is fitted

ACF_FLOOR = 0.05  # a noise's autocorrelation counts until it first falls below this


SCATTER_WINDOW_S = 8.0  # window of the local trend a sensor's scatter is taken about (s)


RATE_WINDOW_S = 2.0  # window of the local descent rate that tells when a canopy has settled (s)


SETTLED_RATE_FACTOR = 1.25  # settled: the local rate within this factor of the steady one


STEADY_RATE_S = 10.0  # the settled descent rate under a canopy is taken over this long (s)


STUCK_RUN_S = 2.0  # a reading repeated exactly for this long (s) ...


STUCK_RUN_SAMPLES = 10  # ... and this many samples is a dead channel


CLIP_RUN_SAMPLES = 3  # a channel's extreme reading met this often is its range's end: clipped


MERGE_SPAN_S = 1.0  # longest span of independent samples merged into one mean (s)


MERGE_FROM_HZ = 10.0  # a series sampled slower is left as it is: its rows are few already


CURVATURE_WINDOW_S = 1.5  # window of the local quadratic whose curvature bounds a merge (s)


CURVATURE_BIAS = 0.1  # a merged mean's curvature bias, at most this share of its sigma (1 %
# of its expected chi-square)


def _scatter(t: np.ndarray, values: np.ndarray) -> np.ndarray | None:
    """`values` less their local quadratic trend over SCATTER_WINDOW_S (a Savitzky-Golay
    filter on a uniform resampling); None where the samples span too short a time."""
    grid = np.arange(t[0], t[-1], 0.1)
    window = min(int(SCATTER_WINDOW_S / 0.1) // 2 * 2 + 1, len(grid) // 2 * 2 - 1)
    if window < 5:
        return None
    return values - np.interp(t, grid, savgol_filter(np.interp(grid, t, values), window, 2))


def scatter_sigma(t: np.ndarray, values: np.ndarray) -> float:
    """Robust sigma (1.4826 MAD) of `values` about their local quadratic trend over
    SCATTER_WINDOW_S (`_scatter`).

    Unlike the second differences this counts disturbances correlated over a
    few seconds, such as the static-pressure swings of a rocket swinging under
    a fast drogue, as noise; the descent itself (speed changing over tens of
    seconds) stays in the trend."""
    r = _scatter(t, values)
    if r is None:
        return second_difference_sigma(values)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def integrated_time(r: np.ndarray) -> float:
    """The integrated autocorrelation time (samples) of the residual series `r`:
    1 + 2 sum_k rho_k, the sum over the lags before rho first falls below `ACF_FLOOR` or
    below 2/sqrt(n), the band within which white noise's sample autocorrelation of n
    samples stays (so that chance correlations of a white series do not add up); 1 for
    fewer than 20 samples."""
    if r.size < MIN_DESCENT_SAMPLES:
        return 1.0
    r = r - r.mean()
    var = float(np.dot(r, r))
    if var == 0.0:
        return 1.0
    floor = max(ACF_FLOOR, 2.0 / np.sqrt(r.size))
    total = 1.0
    for k in range(1, r.size // 4):
        rho = float(np.dot(r[:-k], r[k:])) / var
        if rho < floor:
            break
        total += 2.0 * rho
    return total


def correlation_length(t: np.ndarray, values: np.ndarray) -> int:
    """The integrated autocorrelation time (`integrated_time`, rounded, samples) of
    `values`' scatter about their local trend (`_scatter`): the number of samples that
    carry as much information as one independent sample.  1 for white noise or too few
    samples (under 80)."""
    if t.size < 4 * MIN_DESCENT_SAMPLES:
        return 1
    r = _scatter(t, values)
    if r is None:
        return 1
    return max(1, round(integrated_time(r)))


def settled(t: np.ndarray, steady_end: float = np.inf) -> np.ndarray:
    """Which of the times `t` (s, one canopy's segment) lie in its settled descent: the
    later half of the span up to `steady_end` (the next canopy's charge, or the phase's
    end).  An opening's deceleration or the landing, which a local quadratic trend does
    not follow, would read there as correlated noise."""
    end = min(float(t[-1]), steady_end)
    return (t >= 0.5 * (t[0] + end)) & (t <= end)


def longest_stretch(t: np.ndarray, breaks: list[float]) -> np.ndarray:
    """Which of the times `t` (s, sorted) lie in the later half of their longest stretch
    between `breaks` (s: the deployments and the phase's end): a segment's settled
    descent, whatever openings it spans."""
    edges = sorted({float(t[0]), float(t[-1]), *(b for b in breaks if t[0] < b < t[-1])})
    a, b = max(pairwise(edges), key=lambda e: e[1] - e[0], default=(t[0], t[-1]))
    return (t >= 0.5 * (a + b)) & (t <= b)


def block_sigma(blocks: pd.DataFrame, steady_end: float = np.inf,
                spread: Callable[[np.ndarray, np.ndarray], float] | None = None) -> float:
    """The noise sigma to weigh block means (`independent_blocks`) by: their scatter about
    the local trend (`spread`: robust, `scatter_sigma`, by default) times the square root
    of their own integrated autocorrelation time in the settled descent (`settled`).
    Adjacent blocks of a correlated noise still share its tail (for an AR(1) noise in
    blocks of its integrated time, adjacent means correlate at 0.36), and weighing them as
    independent would state sigmas too small by that root."""
    t, values = blocks["time"].to_numpy(float), blocks.iloc[:, 1].to_numpy(float)
    steady = settled(t, steady_end)
    r = _scatter(t[steady], values[steady]) if steady.sum() >= 2 else None
    tail = 1.0 if r is None else max(1.0, integrated_time(r))
    return (spread or scatter_sigma)(t, values) * float(np.sqrt(tail))


def independent_blocks(frame: pd.DataFrame, steady_end: float = np.inf
                       ) -> tuple[pd.DataFrame, int]:
    """`frame` (``time`` s and one channel) averaged in consecutive blocks of
    `correlation_length` samples, each block's mean at its mean time, blocks never spanning
    a gap (a left-out charge window: over 1.5 sample intervals); with the block size.  The
    correlation is measured in the settled descent (`settled`, up to `steady_end`).

    Block means of correlated noise are nearly independent, weighed at `block_sigma`: a
    fit that weighs every raw sample at the raw scatter would
    count each piece of information that many times over, and state sigmas that many
    times too small.  Over a block (well under a second) the descent's curvature moves the
    mean from the mid-time value by a·L²/24, centimetres against metres of noise."""
    if len(frame) < 2:
        return frame.reset_index(drop=True), 1
    t = frame["time"].to_numpy(float)
    steady = settled(t, steady_end)
    size = correlation_length(t[steady], frame.iloc[:, 1].to_numpy(float)[steady])
    if size <= 1:
        return frame.reset_index(drop=True), 1
    run = np.r_[0, np.cumsum(np.diff(t) > 1.5 * sample_interval(t))]
    position = np.zeros(t.size, dtype=int)
    for r in np.unique(run):
        sel = run == r
        position[sel] = np.arange(sel.sum()) // size
    keys = run * (t.size + 1) + position
    return frame.groupby(keys, sort=True).mean().reset_index(drop=True), size


def accelerometer_blocks(part: pd.DataFrame, steady_end: float = np.inf
                         ) -> tuple[pd.DataFrame, float, int]:
    """One segment of an accelerometer (``time`` s and ``acceleration`` m/s^2: a canopy's
    descent, up to `steady_end`, the next canopy's charge or the phase's end) as what a fit
    should weigh: its samples averaged in blocks of their correlation length
    (`independent_blocks`, each mean at its blocks' mean time), the sigma of those block
    means (`block_sigma` with the RMS scatter, `scatter_rms`: the swing's jolts are part
    of the swing), and the block size (samples; 1 for white noise, where the samples are
    returned as they are).

    A body swinging and spinning under its canopy reads its swing on the axial
    accelerometer as a noise correlated over a fraction of a second (Hedy under its
    drogue, at 100 Hz: lag-one correlation 0.92, integrated time 42 samples); weighed
    sample by sample at the raw scatter, 20,000 samples count as 20,000 independent
    readings of what is about 500 readings' information, and the channel outweighs the
    altimeter (block-averaged to its own correlation length) fifty-fold.  The block means
    carry the steady load (1 g times the axis's cosine) and a descent's slow changes; an
    opening's load peak, over a second, needs the samples and is not passed here."""
    frame = part[["time", "acceleration"]]
    blocks, size = independent_blocks(frame, steady_end)
    return blocks, block_sigma(blocks, steady_end, scatter_rms), size


def scatter_rms(t: np.ndarray, values: np.ndarray) -> float:
    """RMS of `values` about their local quadratic trend over SCATTER_WINDOW_S (`_scatter`):
    the sigma of a disturbance whose tails belong to it.  An accelerometer on a body
    swinging under its canopy reads jolts of g when the swing reverses (both Prometheus
    recorders read +2.5 to +3 g at 148.6-148.8 s under a drogue whose median reading is
    -1.65 g): part of the swing, not glitches, so its variance, not a robust spread of
    its middle, is the noise (under the drogue, 4.6 m/s^2 against 3.5 robust)."""
    r = _scatter(t, values)
    if r is None:
        return second_difference_sigma(values)
    return float(np.sqrt(np.mean(r**2)))


def settled_time(t: np.ndarray, altitude: np.ndarray, t_from: float, t_to: float) -> float:
    """When the descent after a deployment at `t_from` has settled (s): the first time from
    which the local descent rate (slope of a line through `RATE_WINDOW_S` of altitude
    samples, m/s) stays within `SETTLED_RATE_FACTOR` of the steady rate (the median local
    rate over the second half of [`t_from`, `t_to`]) for a further window.  `t_from`
    where the samples are too few to tell."""
    centres = np.arange(t_from + RATE_WINDOW_S / 2, t_to - RATE_WINDOW_S / 2, RATE_WINDOW_S / 2)
    rates = np.array([local_slope(t, altitude, c - RATE_WINDOW_S / 2, c + RATE_WINDOW_S / 2)
                      for c in centres])
    late = centres >= 0.5 * (t_from + t_to)
    if not np.isfinite(rates[late]).any():
        return t_from
    steady = abs(float(np.nanmedian(rates[late])))
    ok = np.abs(rates) <= SETTLED_RATE_FACTOR * steady
    for i in range(centres.size - 2):
        if ok[i] and ok[i + 1] and ok[i + 2]:
            return float(centres[i] - RATE_WINDOW_S / 2)
    return t_from


def local_slope(t: np.ndarray, values: np.ndarray, lo: float, hi: float) -> float:
    """Slope (per s) of a line through the samples in [lo, hi]; NaN with fewer than 4."""
    m = (t >= lo) & (t <= hi)
    if m.sum() < 4:
        return float("nan")
    return float(np.polyfit(t[m] - lo, values[m], 1)[0])


def dead_samples(t: np.ndarray, values: np.ndarray, clipped: bool = False) -> np.ndarray:
    """Which samples a channel did not measure: runs of one exact reading repeated for at
    least `STUCK_RUN_S` and `STUCK_RUN_SAMPLES` samples (a dead or zeroed channel: a real
    sensor's noise, or a descent of metres per second, changes the reading within that),
    and with `clipped`, every sample at the channel's largest or smallest reading where that
    exact reading comes `CLIP_RUN_SAMPLES` times or more (the sensor's range: the force went
    beyond it; a real peak of a noisy channel is not matched to the last digit).  `t` in
    s."""
    if values.size < 2:
        return np.zeros(values.size, dtype=bool)
    change = np.flatnonzero(np.diff(values) != 0.0) + 1
    first, end = np.r_[0, change], np.r_[change, values.size]  # runs [first, end)
    run = end - first
    dead_run = (run >= STUCK_RUN_SAMPLES) & (t[end - 1] - t[first] >= STUCK_RUN_S)
    dead = np.repeat(dead_run, run)
    if clipped:
        for rail in (values.max(), values.min()):
            at_rail = values == rail
            if at_rail.sum() >= CLIP_RUN_SAMPLES:
                dead |= at_rail
    return dead


def dead_note(channel: str, t: np.ndarray, values: np.ndarray, unit: str) -> str:
    """A sentence on the samples `dead_samples` left out of `channel`."""
    readings = ", ".join(f"{v:g}" for v in np.unique(values)[:3])
    return (f"{channel}: {t.size} samples between {t.min():.2f} and {t.max():.2f} s left out: "
            f"the channel repeats one reading ({readings} {unit}) for {STUCK_RUN_S:g} s or "
            "more, or sits at its range's end: it did not measure there")


def merged_blocks(t: np.ndarray, values: np.ndarray, sigma: float) -> tuple[np.ndarray, ...]:
    """Independent samples (`t` s, `values` in the channel's unit, each at noise `sigma`)
    merged into means of 2^k consecutive samples (the normal points of satellite laser
    ranging) wherever the signal is straight enough that a mean at its mean time says
    what the samples say: the times, the means and each mean's sample count.  Its sigma
    is `sigma` / sqrt(count).

    A mean of m samples spanning L s of a signal with curvature y'' lies y'' L^2/24 from
    the value at its mean time.  A merge is kept where that bias is at most
    `CURVATURE_BIAS` of the mean's own sigma, sigma sqrt(dt/L): L^2.5 <= 24 kappa sigma
    sqrt(dt) / |y''|, |y''| the largest within half a `MERGE_SPAN_S` of the local
    quadratic over `CURVATURE_WINDOW_S` (its noise counts as curvature: merges only
    shorten).  Over a steady descent a 100 Hz channel merges to a few hertz without
    losing information (the least-squares fit of a smooth model to the means equals the
    fit to the samples); an opening's deceleration or load peak keeps its samples.  Merges
    never span a gap (over 1.5 sample intervals: a left-out charge window) and never exceed
    `MERGE_SPAN_S`.  A series sampled slower than `MERGE_FROM_HZ` is returned as it is: its
    rows cost little, and means of two or three would only coarsen the residuals a user
    reads (and, under a misfit, raise chi-square/dof, whose excess stays while the noise's
    degrees of freedom merge away)."""
    n = t.size
    counts = np.ones(n, dtype=int)
    if n < 5 or sample_interval(t) > 1.0 / MERGE_FROM_HZ:
        return t, values, counts
    dt = sample_interval(t)
    allowed = np.ones(n, dtype=int)
    run = np.r_[0, np.cumsum(np.diff(t) > 1.5 * dt)]
    for r in np.unique(run):
        idx = np.flatnonzero(run == r)
        window = min(int(CURVATURE_WINDOW_S / dt) // 2 * 2 + 1, idx.size // 2 * 2 - 1)
        if window < 5:
            continue
        curvature = np.abs(savgol_filter(values[idx], window, 2, deriv=2, delta=dt))
        reach = max(1, int(0.5 * MERGE_SPAN_S / dt))
        curvature = maximum_filter1d(curvature, 2 * reach + 1, mode="nearest")
        span = (24.0 * CURVATURE_BIAS * sigma * np.sqrt(dt)
                / np.maximum(curvature, 1e-12)) ** 0.4
        m = np.floor(np.minimum(span, MERGE_SPAN_S) / dt).astype(int)
        allowed[idx] = 2 ** np.floor(np.log2(np.maximum(m, 1))).astype(int)
    starts, sizes = [], []
    i = 0
    while i < n:
        m = int(allowed[i])
        while m > 1 and (i + m > n or run[i + m - 1] != run[i]
                         or int(allowed[i:i + m].min()) < m):
            m //= 2
        starts.append(i)
        sizes.append(m)
        i += m
    first = np.asarray(starts)
    count = np.asarray(sizes)
    merged_t = np.add.reduceat(t, first) / count
    merged_v = np.add.reduceat(values, first) / count
    return merged_t, merged_v, count
