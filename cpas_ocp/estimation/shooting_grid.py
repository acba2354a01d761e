"""The shooting grid, chosen from the dynamics: fine where the motion changes fast, coarse in
steady descent.

Every node lies on the fine lattice t_0 + i h (h the sensor-rate step of
`estimation.default_grid_step`), and every interval is h times a power of
two, at most MAX_INTERVAL_S.  An interval longer than MAX_STEP_S is
integrated in RK4 sub-steps of at most MAX_STEP_S (`substeps_of`), and a
sample inside it is predicted by cubic Hermite interpolation between its
nodes (states and their derivatives), not by stepping from the node before.
The model is simulated once from the offline reduction's values on the
lattice, and an interval of length H <= MAX_STEP_S may start at lattice
point i (a multiple of H / h) where

* **accuracy**: one RK4 step of length H from the simulated state lands
  within ERROR_PER_SECOND * H state scales of where the lattice's steps
  land (per state: at velocity's 100 m/s scale that is a velocity error
  of 1 mm/s per second of flight, an acceleration bias of 1e-4 g, a
  hundredth of an IMU's noise), and
* **stability**: H rho <= STABILITY at both ends, rho the spectral radius
  of the dynamics' Jacobian d f / d x there (RK4 is stable to |lambda h|
  about 2.8; at 0.5 its error in the fastest mode is 2e-4 per step, so
  that mode may stiffen fivefold during the fit before RK4 loses it).

A longer interval (seconds in a steady descent under a canopy, whose drag
relaxes the speed to its terminal value in v / 2g, a few tenths of a
second: stiff for one RK4 step, slow for the motion) may stand where every
lattice interval it covers allows the longest single step, its sub-steps
land within ERROR_PER_SECOND * H state scales of the lattice's end, and the
Hermite interpolant lies within the longest single step's ERROR_PER_SECOND *
MAX_STEP_S of the lattice's states at every lattice point inside it (at the
altitude's 1,000 m scale, 2.5 mm: a hundredth of a barometric altimeter's
noise).

Not with a process of the air's motion (`wind_process`): its knots start at
rest, so the simulation from the guesses cannot show how fast the descent
will follow the air the fit puts in.  On the Prometheus TeleMega log (wind
knots every 4 s, 58 parameters) intervals of 3.2 s took 42 iterations at 1.9
s each where the one-step grid takes 16 at 0.46 s.

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

from cpas_ocp.estimation.simulate import Trajectory, rk4_step, simulate
from cpas_ocp.physics.model import Model

MAX_STEP_S = 0.25  # longest RK4 step (s): of an interval, or of its sub-steps
MAX_INTERVAL_S = 4.0  # longest shooting interval (s), integrated in sub-steps
ERROR_PER_SECOND = 1e-5  # RK4 step error per second of flight, in state scales (1/s)
STABILITY = 0.5  # largest |lambda| H of the dynamics on an interval of length H
SUPPORT = 3  # fine intervals either side of a capture time's window (the B-spline's support)


@dataclass(frozen=True)
class TimeWindow:
    """Where an event or start time may lie (s): [lower, upper], and its first guess."""

    lower: float
    upper: float
    guess: float


def dynamics_grid(model: Model, values: dict[str, float], x0: np.ndarray, t0: float,
                  t1: float, fine_step: float, windows: Sequence[TimeWindow]) -> np.ndarray:
    """The nodes (s) of a shooting grid on [t0, t1] for `model` (see the module docstring).

    `values` are the parameters' first guesses (SI), `x0` the state at t0,
    `fine_step` the lattice step h (s).
    """
    traj = _lattice_trajectory(model, values, x0, t0, t1, fine_step)
    levels = _accuracy_levels(model, values, traj.x, traj.t, traj.captures, fine_step)
    levels = np.minimum(levels, _stability_levels(model, values, traj.x, traj.t,
                                                  traj.captures, fine_step))
    levels = _long_levels(model, values, traj, fine_step, levels)
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
    return t0 + fine_step * _nodes(demanded)


def stable_refinement(nodes: np.ndarray, model: Model, values: dict[str, float],
                      x0: np.ndarray, fine_step: float) -> np.ndarray:
    """`nodes` (s, on the lattice of `fine_step` from nodes[0]) with whatever nodes the
    stability rule adds for `model`.

    A grid chosen for one model serves the models built from its fit (a
    score test's extension, a confirming refit, a comparison), so that their
    chi-squares compare on one grid; but an effect may bring a fast mode the
    fit's model lacks (an elastic riser's spring, at 25 Hz in its null point),
    on which RK4 at the fit's coarse steps would blow up.  There the grid is
    refined; elsewhere it is kept.
    """
    t0 = float(nodes[0])
    traj = _lattice_trajectory(model, values, x0, t0, float(nodes[-1]), fine_step)
    stable = _nodes(_stability_levels(model, values, traj.x, traj.t, traj.captures,
                                      fine_step))
    given = np.rint((np.asarray(nodes) - t0) / fine_step).astype(int)
    return t0 + fine_step * np.union1d(given, stable)


def substeps_of(t: np.ndarray) -> np.ndarray:
    """RK4 sub-steps of each interval of the grid `t` (s): one for an interval of at most
    MAX_STEP_S, else the least power of two that cuts it into steps of at most MAX_STEP_S
    (the steps the grid's accuracy and stability rules checked)."""
    ratio = np.diff(np.asarray(t, dtype=float)) / MAX_STEP_S
    out = np.ones(ratio.size, dtype=int)
    long = ratio > 1.0 + 1e-9
    out[long] = 2 ** np.ceil(np.log2(ratio[long] - 1e-9)).astype(int)
    return out


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
                 levels: np.ndarray) -> np.ndarray:
    """`levels` raised, per lattice interval, to the largest j <= the MAX_INTERVAL_S level
    at which an interval of 2^j h made of `substeps_of` RK4 steps is accurate and its
    Hermite interpolant too, at every level up to j (module docstring), where every
    lattice interval it covers allows the longest single step."""
    top = _max_level(fine_step)
    last = max(top, int(np.floor(np.log2(MAX_INTERVAL_S / fine_step + 1e-9))))
    n = len(levels)
    out = levels.copy()
    allowed = levels >= top
    if last == top or not allowed.any():
        return out
    if any(prm.process_knot for prm in model.parameters):
        return out  # the air held still at the guesses: its motion's time scale is unseen
    x, t = traj.x, traj.t
    p, c = model.parameter_vector(values), model.capture_vector(traj.captures)
    scale = model.state_scales()
    with np.errstate(all="ignore"):
        f = np.asarray(_rhs_function(model).map(len(t))(x.T, t, p, c)).T
    step = rk4_step(model)
    sub = 2**top
    for j in range(top + 1, last + 1):
        span = 2**j
        starts = np.arange(0, n - span + 1, span)
        good = np.zeros(n, dtype=bool)
        cover = np.array([allowed[i:i + span].all() for i in starts], dtype=bool)
        starts = starts[cover]
        if starts.size:
            xe = x[starts].T
            for k in range(span // sub):
                xe = step.map(starts.size)(xe, t[starts + k * sub], sub * fine_step, p, c)
            with np.errstate(all="ignore"):
                error = np.max(np.abs(np.asarray(xe) - x[starts + span].T) / scale[:, None],
                               axis=0)
                inner = starts[:, None] + np.arange(1, span)[None, :]
                guess = hermite_state(x[starts][:, None, :], x[starts + span][:, None, :],
                                      f[starts][:, None, :], f[starts + span][:, None, :],
                                      span * fine_step,
                                      (np.arange(1, span) * fine_step)[None, :, None])
                between = np.max(np.abs(guess - x[inner]) / scale, axis=(1, 2))
            # The sub-steps' error grows with the interval as the lattice's would; the
            # interpolant's may not exceed one longest single step's.
            ok = ((error <= ERROR_PER_SECOND * span * fine_step)
                  & (between <= ERROR_PER_SECOND * sub * fine_step))
            for i in starts[ok]:
                good[i:i + span] = True
        out[good] = j
        allowed = good
    return out


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
    """Per lattice interval, the largest j with 2^j h rho <= STABILITY at both its ends."""
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
    with np.errstate(divide="ignore"):
        node = np.floor(np.log2(STABILITY / (np.maximum(rho, 1e-12) * fine_step)))
    node[~np.isfinite(node)] = 0
    node = np.clip(node, 0, _max_level(fine_step)).astype(int)
    return np.minimum(node[:-1], node[1:])


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
