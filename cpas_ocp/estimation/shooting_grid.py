"""The shooting grid, chosen from the dynamics: fine where the motion changes fast, coarse in
steady descent.

Every node lies on the fine lattice t_0 + i h (h the sensor-rate step of
`estimation.default_grid_step`), and every interval is h times a power of
two, at most MAX_INTERVAL_S.  The model is simulated once from the offline
reduction's values on the lattice, and a single RK4 step of length H <=
MAX_STEP_S may start at lattice point i (a multiple of H / h) where

* **accuracy**: one RK4 step of length H from the simulated state lands
  within ERROR_PER_SECOND * H state scales of where the lattice's steps
  land (per state: at velocity's 100 m/s scale that is a velocity error
  of 1 mm/s per second of flight, an acceleration bias of 1e-4 g, a
  hundredth of an IMU's noise), and
* **stability**: H rho <= STABILITY at both ends, rho the spectral radius
  of the dynamics' Jacobian d f / d x there (RK4 is stable to |lambda h|
  about 2.8; at 0.5 its error in the fastest mode is 2e-4 per step, so
  that mode may stiffen fivefold during the fit before RK4 loses it).

A shooting interval may be longer than its RK4 steps: it is integrated in
sub-steps of the longest single step every lattice interval it covers allows
(at most MAX_SUBSTEPS of them; `ShootingGrid.steps`), and a sample inside it
is predicted by cubic Hermite interpolation between its nodes (states and
their derivatives), not by stepping from the node before.  Such an interval
stands where its sub-steps land within ERROR_PER_SECOND * H state scales of
the lattice's end and the Hermite interpolant lies within one sub-step's
ERROR_PER_SECOND * (its length) of the lattice's states at every lattice
point inside it (for a 0.25 s sub-step at the altitude's 1,000 m scale, 2.5
mm: a hundredth of a barometric altimeter's noise).

A steady descent under a canopy is where a flight spends most of its time.
Under a fast drogue every lattice interval allows the longest single step,
and intervals of seconds stand.  Under a slow canopy the drag relaxes the
speed to its terminal value in 1 / rho = v / 2g, a few tenths of a second:
stability bounds one RK4 step to a fraction of that, and an interval of
such sub-steps spans at most one relaxation time (H rho <= SPAN), so that
the response to whatever the fit changes there (a gust, a drag area) lies
within the nodes, which Gauss-Newton moves one by one.  The same span holds
beside a process of the air's motion (`wind_process`), whose knots start at
rest, so that the simulation from the guesses cannot show how fast the
descent will follow the air the fit puts in.  On the 10-minute log of
`benchmarks/long_log.py` (a drogue at 6 m/s, the air's process; seeds 1-3)
the one-step grid had 7,517 nodes and this one about 3,900; intervals of
0.4 s, a relaxation time and a third, ended in local minima 1.4-27 above
the one-step grid's chi-square, those of 0.2 s in the same minima or lower
on two seeds of the three (4.4 above on the third).  On the Prometheus
TeleMega log (knots every 4 s, 58 parameters) intervals of 3.2 s took 42
iterations at 1.9 s each where the one-step grid took 16 at 0.46 s.

An inflation happens where its start time ends up, not where the reduction
guessed it: every fine demand after a free start time's guess is repeated
for every shift of that time within its bounds, and the bounds' window
itself (with the capture's B-spline support, 3 h either side) is fine.
An observed event's time or a fixed start time is fine over that support.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from cpas_ocp.estimation.fit import Fit
from cpas_ocp.estimation.simulate import Trajectory, rk4_step, simulate
from cpas_ocp.physics.model import Model

MAX_STEP_S = 0.25  # longest RK4 step (s): of an interval, or of its sub-steps
MAX_INTERVAL_S = 4.0  # longest shooting interval (s), integrated in sub-steps
ERROR_PER_SECOND = 1e-5  # RK4 step error per second of flight, in state scales (1/s)
STABILITY = 0.5  # largest |lambda| H of the dynamics on an interval of length H
MAX_SUBSTEPS = 16  # most RK4 sub-steps of one shooting interval
SPAN = 1.0  # largest |lambda| H of a stiff interval, or of any beside a process of the air
SUPPORT = 3  # fine intervals either side of a capture time's window (the B-spline's support)


@dataclass(frozen=True)
class TimeWindow:
    """Where an event or start time may lie (s): [lower, upper], and its first guess."""

    lower: float
    upper: float
    guess: float


@dataclass(frozen=True)
class ShootingGrid:
    """A shooting grid: its nodes (s) and the RK4 sub-steps of each interval."""

    nodes: np.ndarray
    steps: np.ndarray


def dynamics_grid(model: Model, values: dict[str, float], x0: np.ndarray, t0: float,
                  t1: float, fine_step: float, windows: Sequence[TimeWindow]) -> ShootingGrid:
    """The shooting grid on [t0, t1] for `model` (see the module docstring).

    `values` are the parameters' first guesses (SI), `x0` the state at t0,
    `fine_step` the lattice step h (s).
    """
    traj = _lattice_trajectory(model, values, x0, t0, t1, fine_step)
    rho = _spectral_radii(model, values, traj.x, traj.t, traj.captures)
    single = np.minimum(
        _accuracy_levels(model, values, traj.x, traj.t, traj.captures, fine_step),
        _levels_within(rho, fine_step, STABILITY, _max_level(fine_step)))
    levels = _long_levels(model, values, traj, fine_step, single, rho)
    n = len(levels)
    demanded = levels.copy()
    for w in windows:
        lo = int(np.floor((w.lower - t0) / fine_step)) - SUPPORT
        hi = int(np.ceil((w.upper - t0) / fine_step)) + SUPPORT
        demanded[max(lo, 0):max(min(hi, n), 0)] = 0
        guess = int(np.clip(np.floor((w.guess - t0) / fine_step), 0, n))
        after = np.full(n, levels.max(initial=0))
        after[guess:] = levels[guess:]
        for shift in range(lo + SUPPORT - guess, hi - SUPPORT - guess + 1):
            if shift > 0:
                demanded[shift:] = np.minimum(demanded[shift:], after[:n - shift])
            elif shift < 0:
                demanded[:n + shift] = np.minimum(demanded[:n + shift], after[-shift:])
    index = _nodes(demanded)
    return ShootingGrid(t0 + fine_step * index, _interval_steps(index, single))


def stable_refinement(grid: ShootingGrid, model: Model, values: dict[str, float],
                      x0: np.ndarray, fine_step: float) -> ShootingGrid:
    """`grid` (its nodes on the lattice of `fine_step` from its first) with whatever nodes the
    stability rule adds for `model`, each interval in sub-steps no longer than the
    grid's own there.

    A grid chosen for one model serves the models built from its fit (a
    score test's extension, a confirming refit, a comparison), so that their
    chi-squares compare on one grid; but an effect may bring a fast mode the
    fit's model lacks (an elastic riser's spring, at 25 Hz in its null point),
    on which RK4 at the fit's coarse steps would blow up.  There the grid is
    refined; elsewhere it is kept.
    """
    nodes = np.asarray(grid.nodes, dtype=float)
    t0 = float(nodes[0])
    traj = _lattice_trajectory(model, values, x0, t0, float(nodes[-1]), fine_step)
    single = _stability_levels(model, values, traj.x, traj.t, traj.captures, fine_step)
    given = np.rint((nodes - t0) / fine_step).astype(int)
    index = np.union1d(given, _nodes(single))
    # Each new interval's sub-steps: no longer than the given interval's about it, nor
    # than the longest stable single step it covers.
    owner = np.clip(np.searchsorted(given, index[:-1], side="right") - 1, 0, len(given) - 2)
    given_sub = np.diff(given)[owner] // np.asarray(grid.steps)[owner]
    stable_sub = 2 ** np.minimum.reduceat(single, index[:-1])
    sub = np.maximum(np.minimum(given_sub, stable_sub), 1)
    return ShootingGrid(t0 + fine_step * index, np.maximum(np.diff(index) // sub, 1))


def substeps_of(t: np.ndarray) -> np.ndarray:
    """RK4 sub-steps of each interval of a grid `t` (s) given without its own: one for an
    interval of at most MAX_STEP_S, else the least power of two that cuts it into steps
    of at most MAX_STEP_S."""
    ratio = np.diff(np.asarray(t, dtype=float)) / MAX_STEP_S
    out = np.ones(ratio.size, dtype=int)
    long = ratio > 1.0 + 1e-9
    out[long] = 2 ** np.ceil(np.log2(ratio[long] - 1e-9)).astype(int)
    return out


def fitted_steps(fit: Fit) -> np.ndarray:
    """The RK4 sub-steps of each interval of `fit`'s grid: as its estimator recorded them, or
    from the intervals' lengths (`substeps_of`) for a fit made without them."""
    steps = fit.settings.interval_steps
    return substeps_of(fit.t) if steps is None else np.asarray(steps, dtype=int)


def hermite_state(x_a: Any, x_b: Any, f_a: Any, f_b: Any, length: Any, dt: Any) -> Any:
    """The cubic Hermite interpolant (state units) at dt (s) into an interval of `length`
    (s) from its end states `x_a`, `x_b` and their time derivatives `f_a`, `f_b`; CasADi
    or NumPy (broadcast over leading axes).  Its error is length^4/384 times the state's
    fourth derivative: millimetres over seconds of a steady descent."""
    s = dt / length
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * x_a + (s3 - 2 * s2 + s) * length * f_a
            + (3 * s2 - 2 * s3) * x_b + (s3 - s2) * length * f_b)


def _rhs_function(model: Model) -> ca.Function:
    """(x, t, p, c) -> dx/dt of `model`."""
    xs, ts = ca.SX.sym("x", model.nx), ca.SX.sym("t")
    ps = ca.SX.sym("p", len(model.parameters))
    cs = ca.SX.sym("c", len(model.captures))
    return ca.Function("rhs", [xs, ts, ps, cs], [model.rhs(xs, ts, ps, cs)])


def _long_levels(model: Model, values: dict[str, float], traj: Trajectory, fine_step: float,
                 levels: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """`levels` (each lattice interval's longest accurate and stable single step, as a
    power of two of h) raised, per lattice interval, to the largest j <= the
    MAX_INTERVAL_S level at which an interval of 2^j h made of RK4 sub-steps of 2^s h (s
    the least single-step level it covers, at most MAX_SUBSTEPS of them) is accurate and
    its Hermite interpolant too, at every level up to j (module docstring); `rho` the
    spectral radius at each lattice point (`_spectral_radii`)."""
    last = int(np.floor(np.log2(MAX_INTERVAL_S / fine_step + 1e-9)))
    n = len(levels)
    out = levels.copy()
    if last <= 0 or n == 0:
        return out
    x, t = traj.x, traj.t
    # An interval of sub-steps shorter than the longest single step (a stiff descent), or
    # beside a process of the air, spans at most one relaxation time (SPAN).
    top = _max_level(fine_step)
    process = bool(model.series)
    span_limit = _levels_within(rho, fine_step, SPAN, last)
    p, c = model.parameter_vector(values), model.capture_vector(traj.captures)
    scale = model.state_scales()
    with np.errstate(all="ignore"):
        f = np.asarray(_rhs_function(model).map(len(t))(x.T, t, p, c)).T
    step = rk4_step(model)
    most = int(np.log2(MAX_SUBSTEPS))
    good = np.ones(n, dtype=bool)  # lattice intervals an interval of the last level covers
    for j in range(1, last + 1):
        span = 2**j
        starts = np.arange(0, n - span + 1, span)
        cut = starts.size * span  # the lattice intervals whole intervals of 2^j h cover
        sub = levels[:cut].reshape(-1, span).min(axis=1)  # their sub-steps' level
        covered = good[:cut].reshape(-1, span).all(axis=1)
        spans = span_limit[:cut].reshape(-1, span).min(axis=1)
        single = sub >= j  # one RK4 step already spans it
        tried = covered & ~single & (j - sub <= most) & (
            (j <= spans) | ((sub >= top) & (not process)))
        ok = single & covered
        for level in np.unique(sub[tried]):
            pick = tried & (sub == level)
            ok[pick] = _substeps_accurate(step, f, x, t, starts[pick], span, 2**int(level),
                                          fine_step, p, c, scale)
        good = np.zeros(n, dtype=bool)
        good[:cut] = np.repeat(ok, span)
        raise_to = good & (out < j)
        out[raise_to] = j
    return out


def _substeps_accurate(step: ca.Function, f: np.ndarray, x: np.ndarray, t: np.ndarray,
                       starts: np.ndarray, span: int, sub: int, fine_step: float,
                       p: np.ndarray, c: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per start (lattice index), whether an interval of `span` lattice steps from it, made of
    RK4 sub-steps of `sub` lattice steps, lands within ERROR_PER_SECOND times its length
    (state scales) of the lattice's state at its end, and its Hermite interpolant lies
    within one sub-step's ERROR_PER_SECOND * sub * h of the lattice's states inside it:
    the sub-steps' error grows with the interval as the lattice's would; the
    interpolant's may not exceed one sub-step's."""
    xe = x[starts].T
    for k in range(span // sub):
        xe = step.map(starts.size)(xe, t[starts + k * sub], sub * fine_step, p, c)
    with np.errstate(all="ignore"):
        error = np.max(np.abs(np.asarray(xe) - x[starts + span].T) / scale[:, None], axis=0)
        inner = starts[:, None] + np.arange(1, span)[None, :]
        guess = hermite_state(x[starts][:, None, :], x[starts + span][:, None, :],
                              f[starts][:, None, :], f[starts + span][:, None, :],
                              span * fine_step, (np.arange(1, span) * fine_step)[None, :, None])
        between = np.max(np.abs(guess - x[inner]) / scale, axis=(1, 2))
    return ((error <= ERROR_PER_SECOND * span * fine_step)
            & (between <= ERROR_PER_SECOND * sub * fine_step))


def _lattice_trajectory(model: Model, values: dict[str, float], x0: np.ndarray, t0: float,
                        t1: float, fine_step: float) -> Trajectory:
    """The model simulated from `x0` at `values` on the lattice t0 + i h within [t0, t1]."""
    n = int(np.floor((t1 - t0) / fine_step + 1e-9))
    return simulate(model, values, x0, t0, t0 + n * fine_step, step=fine_step)


def _max_level(fine_step: float) -> int:
    """The coarsest power-of-two multiple of `fine_step` within MAX_STEP_S."""
    return max(0, int(np.floor(np.log2(MAX_STEP_S / fine_step + 1e-9))))


def _accuracy_levels(model: Model, values: dict[str, float], x: np.ndarray, t: np.ndarray,
                     captures: dict[str, float], fine_step: float) -> np.ndarray:
    """Per lattice interval, the largest j such that RK4 steps of 2^j h covering it are
    accurate (the accuracy rule) at every level up to j."""
    n = len(t) - 1
    top = _max_level(fine_step)
    levels = np.full(n, top)
    step = rk4_step(model)
    p, c = model.parameter_vector(values), model.capture_vector(captures)
    scale = model.state_scales()
    for j in range(1, top + 1):
        span = 2**j
        starts = np.arange(0, n - span + 1, span)
        if starts.size:
            coarse = np.asarray(step.map(starts.size)(x[starts].T, t[starts], span * fine_step,
                                                      p, c))
            error = np.max(np.abs(coarse - x[starts + span].T) / scale[:, None], axis=0)
            # Where the simulation from the first guesses blew up, nothing is known: fine.
            for i in starts[~(error <= ERROR_PER_SECOND * span * fine_step)]:
                levels[i:i + span] = np.minimum(levels[i:i + span], j - 1)
        uncovered = starts.size * span  # the tail no whole step of this length covers
        levels[uncovered:] = np.minimum(levels[uncovered:], j - 1)
    return levels


def _stability_levels(model: Model, values: dict[str, float], x: np.ndarray, t: np.ndarray,
                      captures: dict[str, float], fine_step: float) -> np.ndarray:
    """Per lattice interval, the largest j <= the MAX_STEP_S level with 2^j h rho <=
    STABILITY at both its ends (`_levels_within`)."""
    return _levels_within(_spectral_radii(model, values, x, t, captures), fine_step,
                          STABILITY, _max_level(fine_step))


def _spectral_radii(model: Model, values: dict[str, float], x: np.ndarray, t: np.ndarray,
                    captures: dict[str, float]) -> np.ndarray:
    """rho (1/s) at each lattice point: the spectral radius of the dynamics' Jacobian
    d f / d x at the states `x`; inf where the simulation blew up."""
    xs = ca.SX.sym("x", model.nx)
    ts = ca.SX.sym("t")
    ps = ca.SX.sym("p", len(model.parameters))
    cs = ca.SX.sym("c", len(model.captures))
    jac = ca.Function("state_jacobian", [xs, ts, ps, cs],
                      [ca.densify(ca.jacobian(model.rhs(xs, ts, ps, cs), xs))])
    a = np.asarray(jac.map(len(t))(x.T, t, model.parameter_vector(values),
                                   model.capture_vector(captures)))
    blocks = a.reshape(model.nx, len(t), model.nx).transpose(1, 0, 2)
    finite = np.all(np.isfinite(blocks), axis=(1, 2))
    rho = np.full(len(t), np.inf)  # a blown-up simulation knows no time scale: fine there
    if np.any(finite):
        rho[finite] = np.max(np.abs(np.linalg.eigvals(blocks[finite])), axis=1)
    return rho


def _levels_within(rho: np.ndarray, fine_step: float, bound: float, top: int) -> np.ndarray:
    """Per lattice interval, the largest j <= `top` with 2^j h rho <= `bound` at both its
    ends (0 where rho is unknown)."""
    with np.errstate(divide="ignore"):
        node = np.floor(np.log2(bound / (np.maximum(rho, 1e-12) * fine_step)))
    node[~np.isfinite(node)] = 0
    node = np.clip(node, 0, top).astype(int)
    return np.minimum(node[:-1], node[1:])


def _interval_steps(index: np.ndarray, single: np.ndarray) -> np.ndarray:
    """RK4 sub-steps of each interval between the lattice indices `index`: its length over
    the longest single step (2^level h) that every lattice interval it covers allows
    (`single`), at least one."""
    sub = 2 ** np.minimum.reduceat(single, index[:-1]).astype(int)
    return np.maximum(np.diff(index) // sub, 1)


def _nodes(levels: np.ndarray) -> np.ndarray:
    """Lattice indices of the nodes: from 0, each interval the longest power of two that its
    start is a multiple of and that every lattice interval it covers allows."""
    n = len(levels)
    nodes = [0]
    i = 0
    while i < n:
        j = int(levels[i])
        while j > 0 and (i % 2**j or i + 2**j > n or np.min(levels[i:i + 2**j]) < j):
            j -= 1
        i += 2**j
        nodes.append(i)
    return np.asarray(nodes)
