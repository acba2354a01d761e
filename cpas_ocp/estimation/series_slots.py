"""Which knots of a series each shooting interval reads: the estimator's model local in time.

A wind process's knots (`ModelContext.time_series`) each act within one knot
spacing of their time, yet a model global in time sums every knot's hat
function in every evaluation, and its Jacobians hold a column per knot: on a
10-minute log with knots every 4 s, 165 columns in every one of 130,000
residual rows and 31,000 continuity rows.  The estimator's pieces are built
on the model local in time instead (`Model(..., series_slots=L)`), and each
interval (with the samples inside it) is given the L consecutive knots about
it: every knot whose hat function is not zero somewhere on the interval, or
within `offset_reach` of it (a lagged sensor reads the state that far away).
The values are those of the global model: the knots left out contribute
exact zeros to its sums.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from cpas_ocp.physics.model import Model

# Most parameters an offset's length may depend on for its reach to be found at the corners
# of their bounds; beyond, the model stays global in time.
MAX_OFFSET_PARAMETERS = 4


@dataclass(frozen=True)
class SeriesSlots:
    """Per series (by name), the knots' parameter names, their times (s) and the first knot
    each shooting interval reads (`bases`, one per interval); `slots` knots are read from
    there on."""

    slots: int
    names: dict[str, tuple[str, ...]]
    times: dict[str, np.ndarray]
    bases: dict[str, np.ndarray]

    def slot_data(self, series: str, intervals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For the instances lying in `intervals` (indices), the knots they read: their
        times (s) and their numbers, each slots x instances."""
        knots = self.bases[series][intervals][None, :] + np.arange(self.slots)[:, None]
        return self.times[series][knots], knots


def offset_reach(model: Model, values: dict[str, float], free: Sequence[str]) -> float | None:
    """How far in time (s) any of the model's outputs may read the state away from its own
    time (`ModelContext.at_time_offset`): the largest |dt| of every offset at the corners of
    the bounds of the free parameters it depends on (the values of the fixed ones); None
    where an offset depends on captured values or on more than MAX_OFFSET_PARAMETERS
    parameters (then no reach is found)."""
    if not model.offsets:
        return 0.0
    _, _, p, c = model.symbols
    reach = 0.0
    for offset in model.offsets:
        dt = ca.SX(offset.dt)
        if ca.depends_on(dt, c):
            return None
        deps = [i for i, prm in enumerate(model.parameters) if ca.depends_on(dt, p[i])]
        if len(deps) > MAX_OFFSET_PARAMETERS:
            return None
        fn = ca.Function("offset_length", [p, c], [dt])
        base = np.array([values.get(prm.name, prm.default) for prm in model.parameters]
                        + [0.0] * (p.numel() - len(model.parameters)), dtype=float)
        sides = [(model.parameters[i].lower, model.parameters[i].upper)
                 if model.parameters[i].name in free else (base[i],) for i in deps]
        for corner in itertools.product(*sides):
            point = base.copy()
            point[deps] = corner
            reach = max(reach, abs(float(fn(point, np.zeros(c.numel())))))
    return reach


def series_slots(model: Model, nodes: np.ndarray, free: Sequence[str], reach: float
                 ) -> SeriesSlots | None:
    """The knots each interval of the grid `nodes` (s) reads, widened by `reach` (s) either
    side, for every series of `model`; None where the model has no series, a knot is not
    free, or the intervals would read every knot of some series anyway (nothing to gain)."""
    if not model.series:
        return None
    free_set = set(free)
    lo, hi = nodes[:-1] - reach, nodes[1:] + reach
    first, last = {}, {}
    for name, (times, names) in model.series.items():
        if not set(names) <= free_set or len(times) < 2:
            return None
        spacing = times[1] - times[0]
        if not np.allclose(np.diff(times), spacing):
            return None
        # Knot k acts on (t_k - spacing, t_k + spacing) (the first and last beyond the ends
        # too): an interval [lo, hi] reads the knots floor((lo - t_0) / spacing) to
        # ceil((hi - t_0) / spacing), widened by a millionth of a spacing against rounding.
        a = np.floor((lo - times[0]) / spacing - 1e-6).astype(int)
        b = np.ceil((hi - times[0]) / spacing + 1e-6).astype(int)
        first[name] = np.clip(a, 0, len(times) - 1)
        last[name] = np.clip(b, 0, len(times) - 1)
    slots = max(int(np.max(last[n] - first[n])) + 1 for n in model.series)
    if any(slots >= len(times) for times, _ in model.series.values()):
        return None
    bases = {n: np.minimum(first[n], len(model.series[n][0]) - slots) for n in model.series}
    return SeriesSlots(slots, {n: names for n, (_, names) in model.series.items()},
                       {n: times for n, (times, _) in model.series.items()}, bases)
