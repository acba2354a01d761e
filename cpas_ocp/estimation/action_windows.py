"""Where in time each parameter acts: the Jacobian entries Ipopt is given.

In multiple shooting every interval's continuity gap and every sample's
residual is a function of one or two node states, the free parameters and
the captured speeds, so the Jacobians' parameter and capture columns are
dense in structure: a Drogue's second stage's fill constant appears in the
RK4 step of every interval, even those long before that stage can start.
Numerically they are mostly zero.  A stage's shape parameters act only
during its inflation, its drag area until the next stage has opened; on
`drogue` at the reduction's start, 92 % of the stored parameter entries are
exact zeros.  Given to Ipopt on the structural pattern they fill the KKT
system with a dense border that MUMPS factorises at every iteration.

`ActionWindows` gives each parameter or capture column a window of time
(s) per matrix: the hull of the times of the rows where its entries are
nonzero at a point, widened by a margin on each side (a drag-area scale
factor acts on the accelerometer's residuals over its stage, and nowhere
on the dynamics).  Entries whose row
lies outside its column's window are left out of the pattern Ipopt sees.
Rows without a time (captures, event-time residuals, priors, an effect's
parameter constraints) and state columns are always kept.

Leaving an entry out of the constraint Jacobian would change what Ipopt
converges to, so the windows are a promise that must be kept where it
matters: `outside` tells whether an evaluation has a nonzero outside them (a
start time that moved further than the margin).  Along the way an iterate
outside them only gets a less exact step; where that persists, and always
at the point Ipopt converges to, the estimator widens the windows to cover
it and restarts Ipopt from that iterate.  The gradient of
chi-square (J'r) is always formed from the whole Jacobian, and the
covariance and the statistical stop linearise the whole model.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class ActionWindows:
    """Per-column time windows over the stored entries of the residual Jacobian J and the
    constraint Jacobian A (both CSC on their fixed patterns, the same columns).

    `row_times` gives, per matrix, the time (s) each row belongs to (NaN: no
    time, always kept); columns from `first_windowed` on (the parameters and
    captures) are windowed, those before it (the node states) kept whole.
    `margin` (s) widens every window on each side; None keeps every entry.
    """

    def __init__(self, patterns: tuple[sp.csc_matrix, sp.csc_matrix],
                 row_times: tuple[np.ndarray, np.ndarray], first_windowed: int,
                 margin: float | None) -> None:
        self.margin = margin
        self._first_windowed = first_windowed
        n_cols = patterns[0].shape[1]
        self._entries = []  # per matrix: (column, row time) of every stored entry
        for pattern, times in zip(patterns, row_times, strict=True):
            column = np.repeat(np.arange(n_cols), np.diff(pattern.indptr))
            time = np.asarray(times, dtype=float)[pattern.indices]
            self._entries.append((column, np.where(column < first_windowed, np.nan, time)))
        # Until fitted to a point, every window is the whole phase.
        self.lower = np.full((2, n_cols), -np.inf)
        self.upper = np.full((2, n_cols), np.inf)
        self._n_cols = n_cols
        self._update_keep()
        self.widenings = 0  # how often a point needed a wider window than the first

    @property
    def active(self) -> bool:
        """Whether any entry is left out (False without a margin)."""
        return self.margin is not None

    def _update_keep(self) -> None:
        """Set `keep` from the windows, and each kept matrix's column pointers."""
        if self.margin is None:
            self.keep = tuple(np.ones(column.size, dtype=bool) for column, _ in self._entries)
        else:
            kept = []
            for (column, time), lower, upper in zip(self._entries, self.lower, self.upper,
                                                    strict=True):
                with np.errstate(invalid="ignore"):
                    inside = (time >= lower[column]) & (time <= upper[column])
                kept.append(np.isnan(time) | inside)
            self.keep = tuple(kept)
        self._indptr = [np.concatenate([[0], np.cumsum(np.bincount(column[keep],
                                                                   minlength=self._n_cols))])
                        for (column, _), keep in zip(self._entries, self.keep, strict=True)]

    def fit(self, values: tuple[np.ndarray, np.ndarray]) -> None:
        """Windows from the nonzeros of J's and A's stored values at a point.

        A parameter that acts nowhere there keeps every entry: its derivatives
        may vanish only at that point (a breathing frequency while the
        amplitudes start at zero), and a window fitted to nothing would leave it
        out of the first steps altogether (a breathing model's fit from its
        nested start then ended in a minimum 2,900 in chi-square above the one
        it reaches with every entry).
        """
        self.lower[:] = np.inf
        self.upper[:] = -np.inf
        self._include(values)
        idle = np.all(np.isinf(self.lower), axis=0)
        idle[:self._first_windowed] = False
        self.lower[:, idle], self.upper[:, idle] = -np.inf, np.inf
        self._update_keep()

    def widen(self, *points: tuple[np.ndarray, np.ndarray]) -> None:
        """Widen the windows to cover the nonzeros of J's and A's stored values at each of
        `points`."""
        self.widenings += 1
        for values in points:
            self._include(values)
        self._update_keep()

    def _include(self, values: tuple[np.ndarray, np.ndarray]) -> None:
        if self.margin is None:
            return
        for (column, time), v, lower, upper in zip(self._entries, values, self.lower,
                                                    self.upper, strict=True):
            acting = (v != 0.0) & ~np.isnan(time)
            np.minimum.at(lower, column[acting], time[acting] - self.margin)
            np.maximum.at(upper, column[acting], time[acting] + self.margin)

    def outside(self, which: int, values: np.ndarray) -> bool:
        """Whether matrix `which` (0: J, 1: A) has a nonzero among the entries left out."""
        return bool(np.any(values[~self.keep[which]] != 0.0))

    def outside_at(self, values: tuple[np.ndarray, np.ndarray]) -> bool:
        """Whether J or A (their stored values at a point) has a nonzero left out."""
        return any(self.outside(i, v) for i, v in enumerate(values))

    def kept_matrix(self, which: int, matrix: sp.csc_matrix) -> sp.csc_matrix:
        """`matrix` (on its fixed pattern) with only the entries kept."""
        keep = self.keep[which]
        return sp.csc_matrix((matrix.data[keep], matrix.indices[keep], self._indptr[which]),
                             shape=matrix.shape)

    def summary(self) -> str:
        """Entries kept, per matrix, e.g. 'J 61,004 of 382,077, A 52,118 of 329,030'."""
        return ", ".join(f"{name} {int(k.sum()):,} of {k.size:,}"
                         for name, k in zip(("J", "A"), self.keep, strict=True))
