"""Several tests' NLPs solved as one, with parameters the tests share held equal.

Tests that fly the same hardware share some of their parameters: one drag
area per canopy type and stage, one pressure recovery fraction per forebody,
one scale per load cell.  Each test keeps its own transcription (states,
parameters, captured values; `Estimator`), and the joint NLP is their direct
sum:

* the decision vector is every test's scaled decision vector, one after the
  other, z = (z_1, ..., z_n);
* the objective is half the sum of the tests' chi-squares, 0.5 sum_i |r_i(z_i)|^2
  (their sensor noise is independent);
* the constraints are every test's (shooting gaps, captures, effect
  constraints) and, per shared parameter with copies p_a, p_b, ... in the
  tests, the links p_a - p_b = 0 (scaled by p_a's scale).

Each test's functions are evaluated on its own slice of z (native code or
the VM, as in a single fit) and their Jacobians placed by one gather of their
nonzeros into the joint pattern, worked out once.  The constraints are
ordered as one test's are: every test's shooting gaps first (they determine
the states after each first node, `uncertainty.reduce_linearisation`), then
every test's capture and effect constraints (whose curvature the Hessian
carries), then the rest and the links.  Ipopt gets the Gauss-Newton Hessian
J'J plus that curvature (`nlp_functions.ipopt_functions`).  The links are
linear, so the covariance at the solution is the KKT covariance of the whole
problem (`uncertainty.kkt_covariance`), every copy of a shared parameter
carrying the same variance.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.action_windows import ActionWindows
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.fit import Fit, SolverStats
from cpas_ocp.estimation.gauss_newton import gauss_newton, gauss_newton_decrement
from cpas_ocp.estimation.kkt_system import Linearisation, linearise
from cpas_ocp.estimation.nlp_functions import bound_violations, ipopt_functions, worst_violation
from cpas_ocp.estimation.solve import STATISTICALLY_CONVERGED, IterationMonitor
from cpas_ocp.estimation.uncertainty import Covariance, kkt_covariance

# The largest constraint violation (scaled) at which a run ended by the statistical test
# counts as feasible.
STATISTICAL_VIOLATION = 1e-6
# Ipopt's barrier parameter and bound push for a start at a neighbour's solution (`warm`):
# from the solution at one population spread, the next spread's (log 2 away) took 28
# iterations (7 s) on three poorly instrumented `fbcp` tests, where the default barrier
# (0.1) pushed the start off its bounds and took 117 (28 s) to the same point.
WARM_BARRIER = 1e-5
WARM_PUSH = 1e-8


@dataclass(frozen=True)
class Link:
    """One shared parameter: its `name` in the joint fit and its copies, (test index,
    parameter name in that test), each a free parameter of its test's estimator."""

    name: str
    members: tuple[tuple[int, str], ...]


class _Gather:
    """Sparse blocks placed into one larger CSC matrix through one gather of their nonzeros.

    Each block (CSC on a fixed pattern) goes to a row offset and a column offset;
    `rows` then reorders the rows of the whole.  The pattern and the gather are
    worked out once; `__call__` takes the blocks' nonzeros (in their CSC order) and
    returns the matrix.
    """

    def __init__(self, blocks: Sequence[tuple[sp.csc_matrix, int, int]], shape: tuple[int, int],
                 rows: np.ndarray | None = None) -> None:
        coo_rows, coo_cols = [], []
        for pattern, r0, c0 in blocks:
            coo = pattern.tocoo()  # in the CSC storage order of the block's nonzeros
            coo_rows.append(coo.row + r0)
            coo_cols.append(coo.col + c0)
        row = np.concatenate(coo_rows) if coo_rows else np.zeros(0, dtype=int)
        col = np.concatenate(coo_cols) if coo_cols else np.zeros(0, dtype=int)
        if rows is not None:
            new_row = np.empty(shape[0], dtype=int)
            new_row[rows] = np.arange(shape[0])
            row = new_row[row]
        self.order = np.lexsort((row, col))  # joint CSC position -> concatenated nonzero
        self.indices = row[self.order].astype(np.int32)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(col, minlength=shape[1]))])
        self.shape = shape

    def __call__(self, data: Sequence[np.ndarray]) -> sp.csc_matrix:
        values = np.concatenate(data)[self.order]
        return sp.csc_matrix((values, self.indices, self.indptr), shape=self.shape)

    def pattern(self) -> sp.csc_matrix:
        """The joint pattern, every stored entry 1."""
        return sp.csc_matrix((np.ones(self.indices.size), self.indices, self.indptr),
                             shape=self.shape)


class JointNlp:
    """The direct sum of several estimators' NLPs, shared parameters linked (module docstring).

    `estimators` are built (not necessarily solved) on the tests; `links` name the
    shared parameters.  `solve(z0)` runs Ipopt from the joint decision vector `z0`
    (`start` builds it from each test's fit); `covariance(z)` is the KKT covariance of
    every free parameter of every test.
    """

    def __init__(self, estimators: Sequence[Estimator], links: Sequence[Link]) -> None:
        self.estimators = list(estimators)
        self.links = list(links)
        sizes = [est.transcription.z.numel() for est in self.estimators]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.nz = int(self.offsets[-1])
        self._order_constraints()
        self._link_rows()
        self._functions_layout()

    # -- layout ------------------------------------------------------------------------

    def _order_constraints(self) -> None:
        """Row order of the joint constraints: every test's shooting gaps, then every
        test's small (curved) constraints, then the rest; links after them."""
        chain, small, rest = [], [], []
        first = 0
        self._small_counts = []
        for est in self.estimators:
            n_g = est.transcription.lbg.size
            gaps = est.transcription.sizes[0] - est.model.nx
            s = est.transcription.small_rows
            chain.append(first + np.arange(gaps))
            small.append(first + np.arange(s.start, s.stop))
            rest.append(first + np.setdiff1d(np.arange(gaps, n_g), np.arange(s.start, s.stop)))
            self._small_counts.append(s.stop - s.start)
            first += n_g
        self._n_test_rows = first
        self._rows = np.concatenate([*chain, *small, *rest]).astype(int)
        self.chain_rows = int(sum(c.size for c in chain))
        n_small = int(sum(self._small_counts))
        self.small_rows = slice(self.chain_rows, self.chain_rows + n_small)

    def column(self, test: int, name: str) -> int:
        """The joint column of free parameter `name` of test `test`."""
        est = self.estimators[test]
        return int(self.offsets[test] + est.transcription.param_index[est.free.index(name)])

    def scale(self, test: int, name: str) -> float:
        """The scale (SI per scaled unit) of free parameter `name` of test `test`."""
        est = self.estimators[test]
        return float(est.pscale[est.free.index(name)])

    def _link_rows(self) -> None:
        """The links' rows: (s_a z_a - s_b z_b) / s_a = 0 for each copy b after the first a."""
        rows, cols, vals = [], [], []
        k = 0
        for link in self.links:
            (t0, n0), *others = link.members
            c0, s0 = self.column(t0, n0), self.scale(t0, n0)
            for t, n in others:
                rows += [k, k]
                cols += [c0, self.column(t, n)]
                vals += [1.0, -self.scale(t, n) / s0]
                k += 1
        self.links_matrix = sp.csc_matrix((vals, (rows, cols)), shape=(k, self.nz))
        self.links_matrix.sort_indices()

    def _functions_layout(self) -> None:
        """The joint Jacobians' patterns and gathers, bounds and the curvature function."""
        ests = self.estimators
        J_blocks, A_blocks = [], []
        J_row = A_row = 0
        for i, est in enumerate(ests):
            J, A = est.transcription.points.patterns()
            J_blocks.append((J, J_row, int(self.offsets[i])))
            A_blocks.append((A, A_row, int(self.offsets[i])))
            J_row += J.shape[0]
            A_row += A.shape[0]
        self.n_residuals = J_row
        n_links = self.links_matrix.shape[0]
        A_blocks.append((self.links_matrix, A_row, 0))
        rows = np.concatenate([self._rows, self._n_test_rows + np.arange(n_links)])
        self._J = _Gather(J_blocks, (self.n_residuals, self.nz))
        self._A = _Gather(A_blocks, (self._n_test_rows + n_links, self.nz), rows)
        self._g_rows = rows
        self.lbg = np.concatenate([np.concatenate([e.transcription.lbg for e in ests])[self._rows],
                                   np.zeros(n_links)])
        self.ubg = np.concatenate([np.concatenate([e.transcription.ubg for e in ests])[self._rows],
                                   np.zeros(n_links)])
        nlps = [e.transcription for e in ests]
        self.lbz = np.concatenate([n.lbz for n in nlps])
        self.ubz = np.concatenate([n.ubz for n in nlps])
        self.param_index = np.concatenate([self.offsets[i] + n.param_index
                                           for i, n in enumerate(nlps)]).astype(int)
        self.pscale = np.concatenate([e.pscale for e in ests])
        self.names = [f"{i}:{f}" for i, e in enumerate(ests) for f in e.free]
        self.dependent = np.concatenate([self.offsets[i] + np.arange(n.model.nx, n.sizes[0])
                                         for i, n in enumerate(nlps)]).astype(int)
        self.pinned = np.concatenate([
            self.offsets[i] + np.flatnonzero(n.lbz[:n.model.nx] == n.ubz[:n.model.nx])
            for i, n in enumerate(nlps)]).astype(int)

    def _slices(self, z: np.ndarray) -> list[np.ndarray]:
        return [z[self.offsets[i]:self.offsets[i + 1]] for i in range(len(self.estimators))]

    # -- the functions Ipopt and the linearisation evaluate -----------------------------

    def residual_value(self, z: np.ndarray) -> np.ndarray:
        """Every test's weighted residuals at `z`, one test after another."""
        return np.concatenate([e.transcription.points.residual_value(zi)
                               for e, zi in zip(self.estimators, self._slices(z), strict=True)])

    def residual_jacobian(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        """The residuals and their Jacobian (CSC on the joint pattern)."""
        parts = [e.transcription.points.residual_jacobian(zi)
                 for e, zi in zip(self.estimators, self._slices(z), strict=True)]
        return np.concatenate([r for r, _ in parts]), self._J([J.data for _, J in parts])

    def constraint_value(self, z: np.ndarray) -> np.ndarray:
        """The joint constraints at `z` (the tests' in the joint order, then the links)."""
        g = np.concatenate([e.transcription.points.constraint_value(zi)
                            for e, zi in zip(self.estimators, self._slices(z), strict=True)])
        return np.concatenate([g[self._rows], self.links_matrix @ z])

    def constraints(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        """The joint constraints and their Jacobian (CSC on the joint pattern)."""
        parts = [e.transcription.points.constraints(zi)
                 for e, zi in zip(self.estimators, self._slices(z), strict=True)]
        g = np.concatenate([gi for gi, _ in parts])
        A = self._A([*(Ai.data for _, Ai in parts), self.links_matrix.data])
        return np.concatenate([g[self._rows], self.links_matrix @ z]), A

    def patterns(self) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """The fixed patterns of the residual and constraint Jacobians."""
        return self._J.pattern(), self._A.pattern()

    def _curvature(self) -> ca.Function:
        """(z, lam_small) -> the upper triangle of the small constraints' curvature: each
        test's on its diagonal block (the links are linear)."""
        z = ca.MX.sym("z", int(self.offsets[-1]))  # the tests' decision vectors
        lam = ca.MX.sym("lam_small", self.small_rows.stop - self.small_rows.start)
        blocks, first = [], 0
        for i, est in enumerate(self.estimators):
            n = self._small_counts[i]
            own = z[int(self.offsets[i]):int(self.offsets[i + 1])]
            blocks.append(est.transcription.curvature()(own, lam[first:first + n]))
            first += n
        return ca.Function("joint_curvature", [z, lam], [ca.diagcat(*blocks)])

    # -- solve, linearise ---------------------------------------------------------------

    def start(self, fits: Sequence[Fit], values: dict[str, float]) -> np.ndarray:
        """The joint decision vector at each test's fit, every copy of a shared parameter
        at `values[link.name]` (SI)."""
        z = []
        for i, (est, fit) in enumerate(zip(self.estimators, fits, strict=True)):
            own = {n: values[link.name] for link in self.links for t, n in link.members
                   if t == i}
            z.append(est.point_from(fit, own))
        return np.concatenate(z)

    def solve(self, z0: np.ndarray, max_iter: int = 500, verbose: bool = False,
              statistical_stop: bool = False, monitor: bool = True, warm: bool = False
              ) -> tuple[np.ndarray, SolverStats]:
        """Ipopt from `z0`; the solution and its statistics.  Raises SolverFailure (with
        Ipopt's status and iteration count) where the run did not converge.

        With `statistical_stop`, a run is also converged where, at a point with the
        constraints met, the Gauss-Newton step would lower chi-square by less than the
        statistical tolerance (`Settings.chi2_step_tol`): the single fit's statistical
        test (`solve.Solver`).  Gauss-Newton's inexact Hessian can leave Ipopt's dual
        infeasibility circling near 0.1 at the optimum for hundreds of iterations (eight
        `fbcp` tests whose canopies' split the data hardly fix, tied by a population).
        With `monitor` the test is made during the run at Ipopt's iterates
        (`IterationMonitor`); without it only once Ipopt has stopped on its
        acceptable-point tests (the slower path, kept to compare: 85 s against 34 s for
        four such tests).  `warm`: `z0` is a neighbouring problem's solution, started
        from at a small barrier parameter (WARM_BARRIER)."""
        tol = self.estimators[0].settings.chi2_step_tol or 0.0
        stop = statistical_stop and tol > 0.0
        began = time.perf_counter()
        functions = ipopt_functions(self, self._curvature(), self.small_rows, self._windows(),
                                    lambda z, outside: None)
        options = {**self.estimators[0].solver.options, **functions.options,
                   "ipopt.max_iter": max_iter, "ipopt.print_level": 5 if verbose else 0}
        if warm:
            options |= {"ipopt.mu_init": WARM_BARRIER, "ipopt.bound_push": WARM_PUSH,
                        "ipopt.bound_frac": WARM_PUSH}
        watch = None
        if stop and monitor:
            watch = IterationMonitor(self.lbz.size, self.lbg.size, self._violations,
                                     lambda z: self._stop_test(z, tol), tol)
            watch.reset(False, (self.lbz, self.ubz))
            options["iteration_callback"] = watch
        elif stop:
            r0 = self.residual_value(np.clip(z0, self.lbz, self.ubz))
            options |= {"ipopt.acceptable_tol": 1e10, "ipopt.acceptable_dual_inf_tol": 1e10,
                        "ipopt.acceptable_iter": 10,
                        "ipopt.acceptable_obj_change_tol": 0.1 * tol / max(1.0, r0 @ r0)}
        solver = ca.nlpsol("joint_reconstruction", "ipopt", functions.nlp, options)
        sol = solver(x0=np.clip(z0, self.lbz, self.ubz), lbx=self.lbz, ubx=self.ubz,
                     lbg=self.lbg, ubg=self.ubg)
        stats = solver.stats()
        z = np.asarray(sol["x"]).ravel()
        status = str(stats["return_status"])
        iterations = int(stats["iter_count"])
        if watch is not None and watch.stopped and watch.point is not None:
            z, status, success = watch.point, STATISTICALLY_CONVERGED, True
        else:
            success = bool(stats["success"])
        r = self.residual_value(z)
        violations = self._violations(self.constraint_value(z))
        worst = worst_violation(violations)
        feasible = float(np.max(violations, initial=0.0)) < STATISTICAL_VIOLATION
        if not success and not (stop and feasible):
            raise SolverFailure(status, iterations, worst, float(r @ r))
        decrement = gauss_newton_decrement(self.linearise(z))
        if not success:
            if decrement >= tol:
                raise SolverFailure(status, iterations, worst, float(r @ r))
            status = STATISTICALLY_CONVERGED
        return z, SolverStats(status, True, iterations, time.perf_counter() - began,
                              0.5 * float(r @ r), worst, decrement, "each test's own fit")

    def _violations(self, g: np.ndarray) -> np.ndarray:
        """How far each constraint value `g` lies outside its bounds (scaled)."""
        return bound_violations(np.asarray(g).ravel(), self.lbg, self.ubg)

    def _stop_test(self, z: np.ndarray, tol: float) -> tuple[float, np.ndarray] | None:
        """(Gauss-Newton decrement, point) where the Ipopt iterate `z` meets the constraints
        within STATISTICAL_VIOLATION and closing what gaps remain changes chi-square by
        less than `tol`; None where it does not (the statistical test then waits)."""
        lin = self.linearise(z)
        if lin.violation > STATISTICAL_VIOLATION:
            return None
        gn = gauss_newton(lin)
        return (gn.decrement, z) if abs(gn.restoration) <= tol else None

    def _windows(self) -> ActionWindows:
        """Windows of action that keep every entry (the joint problem is not windowed)."""
        J, A = self.patterns()
        return ActionWindows((J, A), (np.full(J.shape[0], np.nan), np.full(A.shape[0], np.nan)),
                             0, None)

    def linearise(self, z: np.ndarray) -> Linearisation:
        """The joint problem linearised at `z` (shooting states eliminated per test)."""
        idx = self.param_index
        return linearise(self.residual_jacobian, self.constraints, z, self.lbg, self.ubg, idx,
                         self.lbz[idx], self.ubz[idx], chain_rows=self.chain_rows,
                         dependent=self.dependent, pinned=self.pinned)

    def covariance(self, z: np.ndarray, scale_by_residual: bool = False) -> Covariance:
        """The KKT covariance of every test's free parameters at `z` (SI), named
        "<test index>:<parameter>"; the copies of a shared parameter are equal."""
        return kkt_covariance(self.linearise(z), self.param_index, self.pscale, self.names,
                              scale_by_residual)

    def fits(self, z: np.ndarray, stats: SolverStats) -> list[Fit]:
        """Each test's Fit at the joint solution `z`."""
        return [est.fit_at(zi, stats) for est, zi in zip(self.estimators, self._slices(z),
                                                      strict=True)]
