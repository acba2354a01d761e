"""Several tests' NLPs solved as one, a parameter of each test drawn from a population.

Where tests fly the same kind of hardware but not the same article, a
parameter is neither one value shared by every test (`joint_nlp`'s links) nor
a free value per test: each test's copy is a draw from a population,

    log p_i = mu + eta_i,   eta_i ~ N(0, tau^2)

(the mixed-effects model of NONMEM, Monolix and nlmixr2).  At a given tau the
joint NLP's decision vector is every test's, as in `JointNlp`, followed by one
population mean mu per such parameter; each copy adds one weighted residual,

    r_i = (log p_i - mu) / tau,

to the tests' own, so the objective 0.5 sum |r|^2 is the negative log of the
data's likelihood times the population's density: its minimum is the joint
mode of the tests' parameters and mu.  A copy that its test hardly determines
is drawn towards mu by the others; one its test determines well keeps its own
value.  The residual is linear in log p, so the Gauss-Newton Hessian Ipopt
gets is that of the log-normal density; its Jacobian in the scaled decision
vector z (p = s z) is 1 / (z tau) on the copy and -1 / tau on mu.

A prior on a parameter that may be zero or negative is taken in the parameter
itself, r_i = (p_i - mu) / tau.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.fit import Fit, SolverStats
from cpas_ocp.estimation.joint_nlp import JointNlp, Link
from cpas_ocp.estimation.kkt_system import null_space, reduce_linearisation

# Bounds of a population mean in its own space (log space: a factor of e^30 either way).
MEAN_BOUND = 30.0


@dataclass(frozen=True)
class Population:
    """One parameter drawn per test from a population: its `name` in the hierarchical fit,
    its copies (test index, parameter name in that test), the between-test standard
    deviation `tau` (in log space where `log`, else in SI)."""

    name: str
    members: tuple[tuple[int, str], ...]
    tau: float
    log: bool = True


class HierarchicalNlp(JointNlp):
    """The tests' NLPs with every copy of each `Population` tied to its mean by a residual
    (module docstring), and the `links`' copies held equal as `JointNlp` holds them.  The
    decision vector is the tests' (`JointNlp`) then the means; the means are free
    parameters too, so `covariance(z)` holds them."""

    def __init__(self, estimators: Sequence[Estimator], populations: Sequence[Population],
                 links: Sequence[Link] = ()) -> None:
        super().__init__(estimators, links)
        self.populations = list(populations)
        self.n_test_z = self.nz
        self.n_mean = len(self.populations)
        self.nz = self.n_test_z + self.n_mean
        self.mean_columns = self.n_test_z + np.arange(self.n_mean)
        self.copies = [(g, self.column(t, n), self.scale(t, n))
                       for g, pop in enumerate(self.populations) for t, n in pop.members]
        self.n_residuals += len(self.copies)
        self.lbz = np.concatenate([self.lbz, np.full(self.n_mean, -MEAN_BOUND)])
        self.ubz = np.concatenate([self.ubz, np.full(self.n_mean, MEAN_BOUND)])
        self.param_index = np.concatenate([self.param_index, self.mean_columns]).astype(int)
        self.pscale = np.concatenate([self.pscale, np.ones(self.n_mean)])
        self.names = [*self.names, *(f"mu:{p.name}" for p in self.populations)]
        for pop in self.populations:
            if pop.tau <= 0.0:
                raise ValueError(f"{pop.name}: a between-test standard deviation above 0")

    def solve(self, z0: np.ndarray, max_iter: int = 500, verbose: bool = False,
              statistical_stop: bool = True, monitor: bool = True, warm: bool = False
              ) -> tuple[np.ndarray, SolverStats]:
        """`JointNlp.solve`, ended by the statistical test by default: a population whose
        copies the data hardly fix leaves Gauss-Newton's Hessian far from the exact one
        along them."""
        return super().solve(z0, max_iter, verbose, statistical_stop, monitor, warm)

    def set_tau(self, taus: Sequence[float]) -> None:
        """Each population's tau (the outer loop of a hierarchical fit moves them)."""
        self.populations = [Population(p.name, p.members, float(t), p.log)
                            for p, t in zip(self.populations, taus, strict=True)]

    # -- the copies' residuals ----------------------------------------------------------

    def _prior(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        rows, cols, vals, r = [], [], [], []
        for k, (g, col, s) in enumerate(self.copies):
            pop = self.populations[g]
            mu_col = int(self.mean_columns[g])
            if pop.log:
                r.append((np.log(s * z[col]) - z[mu_col]) / pop.tau)
                vals += [1.0 / (z[col] * pop.tau), -1.0 / pop.tau]
            else:
                r.append((s * z[col] - z[mu_col]) / pop.tau)
                vals += [s / pop.tau, -1.0 / pop.tau]
            rows += [k, k]
            cols += [col, mu_col]
        P = sp.csc_matrix((vals, (rows, cols)), shape=(len(self.copies), self.nz))
        P.sort_indices()
        return np.asarray(r), P

    def _widen(self, M: sp.csc_matrix) -> sp.csc_matrix:
        """`M` (columns of the tests' decision vector) with the means' empty columns."""
        out = sp.hstack([M, sp.csc_matrix((M.shape[0], self.n_mean))], format="csc")
        out.sort_indices()
        return out

    # -- the functions Ipopt and the linearisation evaluate -----------------------------

    def residual_value(self, z: np.ndarray) -> np.ndarray:
        return np.concatenate([super().residual_value(z[:self.n_test_z]), self._prior(z)[0]])

    def residual_jacobian(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        r, J = super().residual_jacobian(z[:self.n_test_z])
        rp, P = self._prior(z)
        full = sp.vstack([self._widen(J), P], format="csc")
        full.sort_indices()
        return np.concatenate([r, rp]), full

    def constraint_value(self, z: np.ndarray) -> np.ndarray:
        return super().constraint_value(z[:self.n_test_z])

    def constraints(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        g, A = super().constraints(z[:self.n_test_z])
        return g, self._widen(A)

    def patterns(self) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        J, A = super().patterns()
        P = self._prior(np.ones(self.nz))[1]
        P.data[:] = 1.0
        full = sp.vstack([self._widen(J), P], format="csc")
        full.sort_indices()
        return full, self._widen(A)

    def _curvature(self) -> ca.Function:
        """The tests' small constraints' curvature, nothing on the means (the copies'
        residuals are in J'J)."""
        tests = super()._curvature()
        z = ca.MX.sym("z", self.nz)
        lam = ca.MX.sym("lam_small", self.small_rows.stop - self.small_rows.start)
        block = tests(z[:self.n_test_z], lam)
        return ca.Function("hierarchical_curvature", [z, lam],
                           [ca.diagcat(block, ca.MX(self.n_mean, self.n_mean))])

    def start(self, fits: Sequence[Fit], values: dict[str, float]) -> np.ndarray:
        """The decision vector at each test's own fit, every copy of a link at
        `values[link.name]` (SI) and each mean at `values[name]` (its own space: log where
        the population is)."""
        return np.concatenate([super().start(fits, values),
                               [values[p.name] for p in self.populations]])

    def laplace_deviance(self, z: np.ndarray) -> float:
        """-2 log of the tests' marginal likelihood at these taus by Laplace's method, up
        to a constant: |r|^2 + 2 sum_copies log tau + log det H, H the Gauss-Newton
        Hessian of 0.5 |r|^2 over every free coordinate (the states eliminated, the means
        integrated too: the restricted likelihood), the copies in log space where their
        population is (log det of the scaled one plus 2 sum log z there)."""
        lin = self.linearise(z)
        ns = null_space(reduce_linearisation(lin))
        eig = ns.H_eigenvalues
        if eig.size and eig.min() <= 0.0:
            return np.inf
        log_tau = sum(np.log(self.populations[g].tau) for g, _, _ in self.copies)
        log_z = sum(np.log(z[col]) for g, col, _ in self.copies if self.populations[g].log)
        r = self.residual_value(z)
        return float(r @ r + 2.0 * log_tau + np.sum(np.log(eig)) + 2.0 * log_z)
