"""Normal points: a long, densely sampled series averaged in short bins where the motion is
slow, each bin one sample with the bin's noise.

A barometric altimeter logging at 100 Hz through a ten-minute steady descent
under a canopy writes 60,000 altitudes of a motion that changes over seconds;
an accelerometer as many readings of a nearly constant specific force.  Each
sample costs the fit a prediction and its derivatives, and the reconstruction
of such a log spends nearly all of its time there.  Averaged over a bin of b
samples with independent noise sigma, the mean carries the same information
as the b samples (its sigma is sigma / sqrt(b), inverse-variance weights where
the sigmas differ) as long as the signal is close to linear over the bin: the
mean of a signal with second derivative y'' over a bin of width w lies
y'' w^2 / 24 from its value at the bin's mean time (0.1 mm for an altitude
changing its descent rate by 0.01 m/s^2 over 0.5 s, against the 4 cm sigma of
50 averaged 0.3 m altitudes).  Satellite laser ranging compresses its data
into such normal points for the same reason.

Where the motion is fast (a canopy's opening, the ejection charges, the first
seconds of a phase) the samples are kept as they are: `keep` lists those
windows.  Within each stretch between them, whole bins of the same number of
samples are formed from the stretch's start; the remainder, fewer than a
bin, is kept as it is, so that within a stretch of equal sigmas the binned
sigma is one value, then the raw one: a sigma that changes at a few times.

The noise must be independent from sample to sample for the bin's sigma to
hold; an altimeter whose noise is correlated over the bin (a filtered
pressure sensor) averages down less, and its fit's chi-square per degree of
freedom says so.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

MAX_BIN_S = 0.5  # longest bin (s): short against a steady descent's changes of speed


def normal_points(t: np.ndarray, y: np.ndarray, sigma: np.ndarray,
                  keep: Sequence[tuple[float, float]], max_bin_s: float = MAX_BIN_S
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (s), values and sigmas (the values' units) of the normal points of the series
    (`t`, `y`, `sigma`; `y` and `sigma` of shape (n,) or (n, channels)), the samples in
    the windows `keep` ((start, end) s) left as they are.

    A bin holds the most samples whose span, at the series' median sampling interval,
    is at most `max_bin_s`; its time is the samples' mean time, its value their
    inverse-variance weighted mean, its sigma (sum 1/sigma^2)^-1/2 per channel.
    """
    t = np.asarray(t, dtype=float)
    y2 = np.asarray(y, dtype=float).reshape(t.size, -1)
    s2 = np.asarray(sigma, dtype=float).reshape(t.size, -1)
    if t.size < 2:
        return t.copy(), np.asarray(y, dtype=float).copy(), np.asarray(sigma, float).copy()
    per_bin = max(1, int(np.floor(max_bin_s / float(np.median(np.diff(t))) + 1e-9)))
    kept = np.zeros(t.size, dtype=bool)
    for a, b in keep:
        kept |= (t >= a) & (t <= b)
    out_t, out_y, out_s = [], [], []
    # Stretches: maximal runs of samples outside every kept window.
    step = np.diff(np.concatenate([[0], (~kept).astype(int), [0]]))
    runs = zip(np.flatnonzero(step == 1), np.flatnonzero(step == -1), strict=True)
    start = 0
    for a, b in runs:
        out_t.append(t[start:a])
        out_y.append(y2[start:a])
        out_s.append(s2[start:a])
        whole = (b - a) // per_bin * per_bin
        if per_bin > 1 and whole:
            w = 1.0 / s2[a:a + whole] ** 2
            shape = (whole // per_bin, per_bin, y2.shape[1])
            wsum = w.reshape(shape).sum(axis=1)
            out_y.append((w * y2[a:a + whole]).reshape(shape).sum(axis=1) / wsum)
            out_s.append(1.0 / np.sqrt(wsum))
            out_t.append(t[a:a + whole].reshape(-1, per_bin).mean(axis=1))
        else:
            whole = 0
        out_t.append(t[a + whole:b])
        out_y.append(y2[a + whole:b])
        out_s.append(s2[a + whole:b])
        start = b
    out_t.append(t[start:])
    out_y.append(y2[start:])
    out_s.append(s2[start:])
    times = np.concatenate(out_t)
    values, sigmas = np.concatenate(out_y), np.concatenate(out_s)
    if np.ndim(y) == 1:
        values, sigmas = values[:, 0], sigmas[:, 0]
    return times, values, sigmas
