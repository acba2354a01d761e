"""The reconstruction NLP's functions for Ipopt, with every model evaluation made once per point.

Ipopt asks for the objective, the constraints, the objective's gradient,
the constraints' Jacobian and the Hessian of the Lagrangian in separate
calls, and the statistical stopping test (`Solver._stop_test`)
linearises the same point once more.  All of them are functions of four
model evaluations at the decision vector z:

* the weighted residuals r(z) and the constraints g(z) (at trial points of
  the line search, values only), and
* r with its Jacobian J(z), g with its Jacobian A(z) (at accepted points).

Given to Ipopt as CasADi expressions, each function re-evaluated what it
needed: on `drogue` J three times and A twice per iteration.  Here each is
evaluated at most once per point, in native code through CasADi's function
buffer into NumPy arrays (`FunctionBuffer`), and Ipopt's functions are
assembled from them (`ipopt_functions`):

* objective 0.5 |r|^2 and gradient J'r (SciPy, J on its fixed pattern);
* the Gauss-Newton Hessian J'J (SciPy's sparse product, which skips the
  Jacobian's numerical zeros: 3 ms on `drogue` where CasADi's product on
  J's structural pattern took 39) plus the curvature of the few capture and
  effect constraints, scattered into a pattern fixed for the solve.

The constraint Jacobian and the J in J'J are given on the entries each
parameter's window of action keeps (`action_windows`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import casadi as ca
import numpy as np
import scipy.sparse as sp

from cpas_ocp.estimation.action_windows import ActionWindows
from cpas_ocp.estimation.compiled import advance_compilers
from cpas_ocp.estimation.function_buffer import FunctionBuffer

POINTS_KEPT = 2  # the accepted iterate and the line search's latest trial point
# Model evaluations a run makes in the VM before it switches to native code compiled
# meanwhile.  The switch rebuilds the point functions (0.5 s on `drogue`) to save about
# 25 ms an evaluation there: it pays only in a long run.  A run that has gone on this long
# is likely to go on as long again; a short one (a fit of `drogue` from its reduction
# makes 25) ends in the VM and leaves the compiled code to the next run
# (`benchmarks/compile_cost.py`).
SWITCH_AFTER = 40


# Seconds of model evaluations in the VM after which a run switches to native code as soon
# as it is ready, however few evaluations it has made: on a 10-minute 100 Hz rocket log
# (131,000 residuals) one residual Jacobian in the VM took a minute, and forty of them
# would have taken the fit past half an hour.
SWITCH_AFTER_S = 10.0


class PointEvaluations:
    """The four model evaluations of the NLP, each kept for the last POINTS_KEPT points.

    `residual_value(z) -> r`, `residual_jacobian(z) -> (r, J)`,
    `constraint_value(z) -> g` and `constraints(z) -> (g, A)`, all of the
    scaled decision vector; r and g are taken from a Jacobian evaluation at
    the same point where there is one.
    """

    def __init__(self, residual_value: ca.Function, residual_jacobian: ca.Function,
                 constraint_value: ca.Function, constraints: ca.Function,
                 switch: Callable[[], Sequence[ca.Function] | None] | None = None) -> None:
        """`switch`, where given, is asked before each new evaluation from the
        SWITCH_AFTER-th on (or once the evaluations have taken SWITCH_AFTER_S seconds) for
        the same four functions in faster form (native code compiled
        meanwhile); once it gives them, they replace these (on the same patterns) and it is
        not asked again."""
        self._buffers = {name: FunctionBuffer(fn) for name, fn in (
            ("r", residual_value), ("rJ", residual_jacobian),
            ("g", constraint_value), ("gA", constraints))}
        self._kept: dict[str, list[tuple[bytes, list]]] = {name: [] for name in self._buffers}
        self.evaluations = dict.fromkeys(self._buffers, 0)  # model evaluations made, per kind
        self.seconds = 0.0  # spent in model evaluations before the switch
        self._switch = switch
        self.switched_at: int | None = None  # the evaluations made before the switch

    def patterns(self) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """The fixed patterns of the residual and constraint Jacobians."""
        return self._buffers["rJ"].pattern(1), self._buffers["gA"].pattern(1)

    def _maybe_switch(self) -> None:
        if self._switch is None:
            return
        if sum(self.evaluations.values()) < SWITCH_AFTER and self.seconds < SWITCH_AFTER_S:
            advance_compilers()
            return
        functions = self._switch()
        if functions is None:
            return
        self._switch = None
        for name, fn in zip(self._buffers, functions, strict=True):
            old = self._buffers[name].fn
            assert all(fn.sparsity_out(i) == old.sparsity_out(i) for i in range(fn.n_out()))
            self._buffers[name] = FunctionBuffer(fn)
        self.switched_at = sum(self.evaluations.values())

    def _lookup(self, name: str, key: bytes) -> list | None:
        for k, value in self._kept[name]:
            if k == key:
                return value
        return None

    def _get(self, name: str, z: np.ndarray) -> list:
        key = np.ascontiguousarray(z, dtype=float).tobytes()
        found = self._lookup(name, key)
        if found is None:
            self._maybe_switch()
            buffer = self._buffers[name]
            start = time.perf_counter()
            found = [buffer.shaped(i, v) for i, v in enumerate(buffer.nonzeros(z))]
            if self._switch is not None:
                self.seconds += time.perf_counter() - start
            self.evaluations[name] += 1
            self._kept[name] = [(key, found), *self._kept[name][:POINTS_KEPT - 1]]
        return found

    def _value(self, value: str, with_jacobian: str, z: np.ndarray) -> np.ndarray:
        key = np.ascontiguousarray(z, dtype=float).tobytes()
        both = self._lookup(with_jacobian, key)
        return both[0] if both is not None else self._get(value, z)[0]

    def residual_value(self, z: np.ndarray) -> np.ndarray:
        """Weighted residuals r(z)."""
        return self._value("r", "rJ", z)

    def residual_jacobian(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        """r(z) and its Jacobian J(z) (CSC on the function's fixed pattern)."""
        r, J = self._get("rJ", z)
        return r, J

    def constraint_value(self, z: np.ndarray) -> np.ndarray:
        """Constraints g(z)."""
        return self._value("g", "gA", z)

    def constraints(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        """g(z) and its Jacobian A(z) (CSC on the function's fixed pattern)."""
        g, A = self._get("gA", z)
        return g, A


def bound_violations(g: np.ndarray, lbg: np.ndarray, ubg: np.ndarray) -> np.ndarray:
    """How far each constraint value in `g` lies outside its bounds [lbg, ubg] (scaled)."""
    return np.maximum(lbg - g, 0) + np.maximum(g - ubg, 0)


def worst_violation(violations: np.ndarray) -> str:
    """The largest of `bound_violations` and where, in words ("" without constraints)."""
    if not violations.size:
        return ""
    return f"index {int(np.argmax(violations))}, violation {float(np.max(violations)):.3g}"


class PointFunctions(Protocol):
    """What Ipopt's functions are assembled from: the residuals and constraints of the
    scaled decision vector with their Jacobians on fixed patterns (`PointEvaluations` of
    one test, `joint_nlp.JointNlp` of several)."""

    def residual_value(self, z: np.ndarray) -> np.ndarray: ...

    def residual_jacobian(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]: ...

    def constraint_value(self, z: np.ndarray) -> np.ndarray: ...

    def constraints(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]: ...

    def patterns(self) -> tuple[sp.csc_matrix, sp.csc_matrix]: ...


class _Oracle(ca.Callback):
    """One of Ipopt's functions, computed in Python into CasADi's output buffers.

    `compute(inputs)` gets the inputs as NumPy vectors of nonzeros and returns
    every output's nonzeros (in the declared pattern's order).
    """

    def __init__(self, name: str, inputs: Sequence[tuple[str, ca.Sparsity]],
                 outputs: Sequence[tuple[str, ca.Sparsity]],
                 compute: Callable[[list[np.ndarray]], list[np.ndarray | float]]) -> None:
        ca.Callback.__init__(self)
        self._inputs, self._outputs, self._compute = list(inputs), list(outputs), compute
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._inputs)

    def get_n_out(self) -> int:
        return len(self._outputs)

    def get_name_in(self, i: int) -> str:
        return self._inputs[i][0]

    def get_name_out(self, i: int) -> str:
        return self._outputs[i][0]

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return self._inputs[i][1]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return self._outputs[i][1]

    def has_eval_buffer(self) -> bool:
        return True

    def eval_buffer(self, arg: list, res: list) -> int:
        inputs = [np.frombuffer(a, dtype=float) if a is not None else np.zeros(0)
                  for a in arg]
        for target, value in zip(res, self._compute(inputs), strict=True):
            if target is not None:  # an output Ipopt did not ask for is a null buffer
                np.frombuffer(target, dtype=float)[:] = value
        return 0


@dataclass
class IpoptFunctions:
    """The NLP for `ca.nlpsol` ("x", "f", "g" of callbacks) and Ipopt's derivative options.

    The callbacks must outlive the solver, which keeps only references:
    hold this object as long as the solver.
    """

    nlp: dict
    options: dict
    callbacks: list[_Oracle]


class MarquardtDamping:
    """Levenberg-Marquardt damping of the Gauss-Newton Hessian, adapted to the progress made.

    Gauss-Newton takes the curvature of chi-square to be J'J's, leaving out
    that of the residuals themselves (sum r_i H_i).  With a misspecified
    model the residuals are large and that curvature is not small along
    the directions the data hardly determine: the Gauss-Newton step
    overshoots there, Ipopt's line search cuts it again and again, and the
    run crawls (`drogue` with added mass left out: 500 iterations).  After
    every iteration the chi-square change of the step just taken is
    compared with what the Gauss-Newton model predicted for it; where less
    than a quarter of it came true, the Hessian Ipopt is given becomes
    J'J + mu diag(J'J) with mu raised fourfold (from MU_START), which shortens
    the step most along the weakly determined directions; where more than
    three quarters came true, mu falls threefold, to zero below MU_FLOOR.  A
    model that fits its data keeps mu = 0: Ipopt's steps are unchanged.
    Only steps between nearly feasible iterates (every constraint within
    FEASIBLE of its bounds, scaled) are judged: a step that also closes
    shooting gaps trades chi-square for feasibility, and its chi-square
    change says nothing of the model (with elastic risers, judging those
    held the damping up and a refit that had converged in 60 iterations
    stopped at 150).
    """

    MU_START = 0.01
    MU_FLOOR = 1e-4
    FEASIBLE = 1e-4

    def __init__(self, points: PointEvaluations, lbg: np.ndarray, ubg: np.ndarray) -> None:
        self.points = points
        self._lbg, self._ubg = lbg, ubg
        self.reset()

    def reset(self) -> None:
        """Start a run undamped."""
        self.mu = 0.0
        self._last: tuple[np.ndarray, np.ndarray, sp.csc_matrix] | None = None

    def observe(self, z: np.ndarray) -> None:
        """Account for the step that ended at the accepted iterate `z`."""
        g = self.points.constraint_value(z)
        if np.any(g < self._lbg - self.FEASIBLE) or np.any(g > self._ubg + self.FEASIBLE):
            self._last = None
            return
        r, J = self.points.residual_jacobian(z)
        if self._last is not None:
            z0, r0, J0 = self._last
            predicted_r = r0 + J0 @ (z - z0)
            predicted = float(predicted_r @ predicted_r - r0 @ r0)
            actual = float(r @ r - r0 @ r0)
            if predicted < 0.0:  # a step the model expected to lower chi-square
                ratio = actual / predicted
                if ratio < 0.25:
                    self.mu = max(4.0 * self.mu, self.MU_START)
                elif ratio > 0.75:
                    self.mu = self.mu / 3.0 if self.mu / 3.0 >= self.MU_FLOOR else 0.0
        self._last = (np.array(z, dtype=float), r, J)


def ipopt_functions(points: PointFunctions, curvature: ca.Function, small_rows: slice,
                    windows: ActionWindows, checked: Callable[[np.ndarray, bool], None],
                    damping: MarquardtDamping | None = None,
                    levenberg: tuple[np.ndarray, float] | None = None) -> IpoptFunctions:
    """Ipopt's objective, constraints and derivatives from `points` (see the module docstring).

    The Hessian is triu(sigma J'J) + curvature(z, lam_small), the latter the
    upper triangle of the curvature of the few small constraints whose rows
    `small_rows` locates in g; with `damping`, sigma mu diag(J'J) is added;
    with `levenberg` = (columns, delta), sigma delta on the diagonal at the
    given columns of z (the scaled free parameters).

    The Levenberg term bounds the step along a parameter the data hardly
    determine where the iterate stands (data curvature well below delta per
    scaled unit squared, i.e. a standard error larger than the parameter's
    own scale): Gauss-Newton would move it by the gradient over a nearly
    vanishing curvature, far beyond where its linearisation holds.  With
    delta = 1 the step there is at most the gradient, in the units of the
    parameter's scale.  It shapes the path only: the Hessian is an
    approximation either way, and the KKT points, hence the fit, are those
    of the undamped problem (the statistical stop and the covariance use
    J'J alone).
    The constraint Jacobian and J in J'J carry only the entries `windows`
    keeps; at every iterate (once, with its Hessian) `checked(z, outside)`
    says whether either Jacobian has a nonzero among the entries left out,
    which the values Ipopt gets then miss (the estimator widens the windows
    and restarts where that persists).  The gradient J'r uses every entry.
    """
    J_pattern, A_pattern = points.patterns()
    nz, ng = J_pattern.shape[1], A_pattern.shape[0]
    kept_J, kept_A = (windows.kept_matrix(i, p) for i, p in enumerate((J_pattern, A_pattern)))
    x_in = ("x", ca.Sparsity.dense(nz, 1))
    p_in = ("p", ca.Sparsity(0, 1))
    dense = ca.Sparsity.dense
    layout = _HessianLayout.of(kept_J, FunctionBuffer(curvature), levenberg)

    def objective(a: list[np.ndarray]) -> list:
        r = points.residual_value(a[0])
        return [0.5 * float(r @ r)]

    def gradient(a: list[np.ndarray]) -> list:
        r, J = points.residual_jacobian(a[0])
        return [0.5 * float(r @ r), J.T @ r]

    def constraint_value(a: list[np.ndarray]) -> list:
        return [points.constraint_value(a[0])]

    def constraint_jacobian(a: list[np.ndarray]) -> list:
        g, A = points.constraints(a[0])
        return [g, A.data[windows.keep[1]]]

    def lagrangian_hessian(a: list[np.ndarray]) -> list:
        z, _, sigma, lam_g = a
        _, J = points.residual_jacobian(z)
        checked(z, windows.outside(0, J.data)
                or windows.outside(1, points.constraints(z)[1].data))
        mu = damping.mu if damping is not None else 0.0
        return [layout.values(z, J, windows.kept_matrix(0, J), float(sigma[0]),
                              lam_g[small_rows], mu)]

    f = _Oracle("objective", [x_in], [("f", dense(1, 1))], objective)
    g = _Oracle("constraint_value", [x_in], [("g", dense(ng, 1))], constraint_value)
    grad_f = _Oracle("grad_f", [x_in, p_in], [("f", dense(1, 1)), ("grad_f_x", dense(nz, 1))],
                     gradient)
    jac_g = _Oracle("jac_g", [x_in, p_in], [("g", dense(ng, 1)), ("jac_g_x", _casadi(kept_A))],
                    constraint_jacobian)
    hess_lag = _Oracle("gauss_newton", [x_in, p_in, ("lam_f", dense(1, 1)),
                                        ("lam_g", dense(ng, 1))],
                       [("hess_gamma_x_x", _casadi(layout.pattern))], lagrangian_hessian)
    x = ca.MX.sym("x", nz)
    return IpoptFunctions(
        {"x": x, "f": f(x), "g": g(x)},
        # The NLP's expressions are callbacks without derivatives: CasADi must not build
        # its own gradient of the Lagrangian (there are no NLP parameters to report on).
        {"grad_f": grad_f, "jac_g": jac_g, "hess_lag": hess_lag, "no_nlp_grad": True,
         "calc_lam_p": False},
        [f, g, grad_f, jac_g, hess_lag])


@dataclass
class _HessianLayout:
    """The upper triangle of the Lagrangian's Hessian as Ipopt takes it: its `pattern`
    (J'J on the entries the action windows keep, the small constraints' curvature, the
    Levenberg columns), the column-major `keys` of its entries, and where in them the
    curvature's nonzeros, the diagonal and the Levenberg columns (term `delta`) go."""

    pattern: sp.csc_matrix
    keys: np.ndarray
    curvature: FunctionBuffer
    curvature_at: np.ndarray
    diagonal: np.ndarray
    diagonal_at: np.ndarray
    levenberg_at: np.ndarray
    delta: float

    @classmethod
    def of(cls, kept_J: sp.csc_matrix, curvature: FunctionBuffer,
           levenberg: tuple[np.ndarray, float] | None) -> _HessianLayout:
        nz = kept_J.shape[1]
        curvature_pattern = curvature.pattern(0)
        columns, delta = levenberg if levenberg is not None else (np.zeros(0, dtype=int), 0.0)
        on_columns = sp.csc_matrix((np.ones(columns.size), (columns, columns)), shape=(nz, nz))
        pattern = (sp.triu(abs(kept_J).T @ abs(kept_J), format="csc") + curvature_pattern
                   + on_columns)
        pattern.sort_indices()
        keys = _column_major_keys(pattern)
        diagonal = np.flatnonzero(pattern.diagonal())
        return cls(pattern, keys, curvature,
                   np.searchsorted(keys, _column_major_keys(curvature_pattern)), diagonal,
                   np.searchsorted(keys, diagonal * (nz + 1)),
                   np.searchsorted(keys, columns.astype(np.int64) * (nz + 1)), delta)

    def values(self, z: np.ndarray, J: sp.csr_matrix, kept: sp.csc_matrix, sigma: float,
               lam_small: np.ndarray, mu: float) -> np.ndarray:
        """The Hessian's values at `z`: sigma J'J on the kept entries, the curvature of the
        small constraints at their multipliers `lam_small`, sigma delta on the Levenberg
        columns, and with Marquardt damping `mu` > 0, sigma mu diag(J'J)."""
        nz = self.pattern.shape[1]
        product = sp.triu(kept.T @ kept, format="coo")
        out = np.zeros(self.keys.size)
        out[np.searchsorted(self.keys, product.col.astype(np.int64) * nz + product.row)] = \
            sigma * product.data
        out[self.curvature_at] += self.curvature.nonzeros(z, lam_small)[0]
        out[self.levenberg_at] += sigma * self.delta
        if mu > 0.0:
            squares = np.asarray(J.multiply(J).sum(axis=0)).ravel()
            out[self.diagonal_at] += sigma * mu * squares[self.diagonal]
        return out


def _column_major_keys(matrix: sp.csc_matrix) -> np.ndarray:
    """col * n_rows + row of every stored entry of a CSC matrix with sorted indices
    (increasing)."""
    column = np.repeat(np.arange(matrix.shape[1], dtype=np.int64), np.diff(matrix.indptr))
    return column * matrix.shape[0] + matrix.indices


def _casadi(matrix: sp.csc_matrix) -> ca.Sparsity:
    """The pattern of a CSC matrix (sorted indices) as a CasADi sparsity."""
    return ca.Sparsity(matrix.shape[0], matrix.shape[1], matrix.indptr.tolist(),
                       matrix.indices.tolist())
