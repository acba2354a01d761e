"""A population whose tests fly several canopies of a type: test-level and canopy-level spread.

The canopies of one test share the vehicle, the air, the instruments'
calibration and the event timing.  So each test is one observation here: the
stacked estimates y_i of its m_i canopies' k parameters (canopy by canopy),
with their whole covariance V_i from the test's own fit, the terms between
canopies included (covariances.csv: where a load cell's scale is shared, two
canopies' drag areas are anti-correlated near -1, and their sum is known far
better than either).  The model is

    y_ic = B x_ic + u_i + eta_ic + e_ic,
    u_i ~ N(0, Omega_T)    (shared by the canopies of test i: its day, its hardware)
    eta_ic ~ N(0, Omega_C) (each canopy's own)
    e_i ~ N(0, V_i)        (the test's estimation noise, across its canopies)

so the marginal covariance of test i is S_i = J ⊗ Omega_T + I ⊗ Omega_C + V_i
(J the m_i x m_i matrix of ones, I the identity).  Omega_T and Omega_C are told
apart only by tests flying two or more canopies of the population; with one
canopy per test only their sum is determined, and the population model of
`population_model` is the one to use.

As there, positive parameters are modelled in log space, B is the generalised
least-squares estimate given the Omegas, the Omegas maximise the restricted
likelihood (REML), each coefficient's interval is Student-t on
(tests - columns) degrees of freedom with the Knapp-Hartung variance, and each
standard deviation's interval is its profile likelihood.  The derivative of
the log-likelihood with respect to S_i, G_i = 1/2 (W r r' W - W [+ W X A^-1
X' W with REML]), W = S_i^-1, gives d/dOmega_T as the sum of all k x k blocks
of G_i and d/dOmega_C as the sum of its diagonal blocks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from cpas_ocp.blas_threads import one_thread
from cpas_ocp.campaign.population_model import (
    LEVEL,
    TAU_FLOOR,
    Interval,
    OmegaForm,
    PopulationData,
    PopulationInputError,
    bounded_maximum,
    omega_bounds,
    profile_interval,
    search_scale,
)


@dataclass(frozen=True)
class NestedData:
    """The estimates of one population, a test at a time, in the model's space.

    Per test i: `y[i]` (m_i k,) its canopies' estimates, canopy by canopy; `V[i]`
    (m_i k, m_i k) their covariance; `X[i]` (m_i, p) each canopy's design row;
    `openings[i]` each canopy's label.  `names`, `log` and `columns` as in
    `PopulationData`.
    """

    names: tuple[str, ...]
    log: tuple[bool, ...]
    columns: tuple[str, ...]
    tests: tuple[str, ...]
    openings: tuple[tuple[str, ...], ...]
    y: tuple[np.ndarray, ...]
    V: tuple[np.ndarray, ...]
    X: tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        k, p = len(self.names), len(self.columns)
        for i, test in enumerate(self.tests):
            m = len(self.openings[i])
            if (self.y[i].shape != (m * k,) or self.V[i].shape != (m * k, m * k)
                    or self.X[i].shape != (m, p)):
                raise PopulationInputError(f"{test}: shapes do not agree")
            if not (np.isfinite(self.y[i]).all() and np.isfinite(self.V[i]).all()):
                raise PopulationInputError(f"{test}: an estimate or a covariance is not "
                                           "finite")
            if np.linalg.eigvalsh(0.5 * (self.V[i] + self.V[i].T)).min() <= 0.0:
                raise PopulationInputError(f"{test}: the covariance of its canopies' "
                                           "estimates is not positive definite")
        if max(len(o) for o in self.openings) < 2:
            raise PopulationInputError("no test flies two or more canopies of the "
                                       "population: test-level and canopy-level spread "
                                       "cannot be told apart")
        if len(self.tests) < p + 2:
            raise PopulationInputError(f"{len(self.tests)} tests for {p} mean "
                                       f"coefficient(s) per parameter: at least {p + 2}")

    @property
    def k(self) -> int:
        return len(self.names)

    @property
    def p(self) -> int:
        return len(self.columns)

    @property
    def observations(self) -> int:
        """Every estimate of every canopy of every test."""
        return sum(len(y) for y in self.y)

    @classmethod
    def from_openings(cls, data: PopulationData, tests: Sequence[str],
                      blocks: dict[str, np.ndarray]) -> NestedData:
        """`data`'s openings gathered by their test (`tests`, one per opening, in the
        openings' order); `blocks[test]` the covariance of that test's openings' estimates
        in the model's space, canopy by canopy (the diagonal blocks `data.V`'s)."""
        order = list(dict.fromkeys(tests))
        rows = {t: [i for i, u in enumerate(tests) if u == t] for t in order}
        return cls(data.names, data.log, data.columns, tuple(order),
                   tuple(tuple(data.openings[i] for i in rows[t]) for t in order),
                   tuple(data.y[rows[t]].reshape(-1) for t in order),
                   tuple(blocks[t] for t in order),
                   tuple(data.X[rows[t]] for t in order))


@dataclass(frozen=True)
class _Batch:
    """The tests with m canopies, stacked: design kron(X_i, I_k) (n, m k, k p) with the
    coefficients ordered column by column, estimates (n, m k), covariances (n, m k, m k)."""

    m: int
    rows: tuple[int, ...]
    design: np.ndarray
    y: np.ndarray
    V: np.ndarray


def _batches(data: NestedData) -> list[_Batch]:
    out = []
    for m in sorted({len(o) for o in data.openings}):
        rows = tuple(i for i, o in enumerate(data.openings) if len(o) == m)
        design = np.stack([np.kron(data.X[i], np.eye(data.k)) for i in rows])
        out.append(_Batch(m, rows, design, np.stack([data.y[i] for i in rows]),
                          np.stack([data.V[i] for i in rows])))
    return out


@dataclass(frozen=True)
class _Evaluation:
    log_likelihood: float
    beta: np.ndarray  # (k p,), column by column
    information: np.ndarray  # (k p, k p)
    W: list[np.ndarray]  # per batch (n, m k, m k)
    residuals: list[np.ndarray]  # per batch (n, m k)
    quad: float  # sum of r' W r over the tests


class NestedModel:
    """The likelihood of `NestedData` in Omega_T's and Omega_C's parameters (`OmegaForm`
    each: log tau, then the partial correlations' atanh where full), one vector: Omega_T's
    first."""

    def __init__(self, data: NestedData, full_omega: bool, reml: bool) -> None:
        self.data, self.reml = data, reml
        self.form = OmegaForm(data.k, full_omega and data.k > 1)
        self.batches = _batches(data)
        # Every canopy's estimates and their variances, one row per canopy.
        self.estimates = np.concatenate([y.reshape(-1, data.k) for y in data.y])
        self.variances = np.concatenate([np.diag(v).reshape(-1, data.k) for v in data.V])
        self.spread = np.maximum(search_scale(self.estimates, self.variances), 1e-12)
        self.floor = TAU_FLOOR * self.spread

    @property
    def size(self) -> int:
        return 2 * self.form.size

    def omegas(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = self.form.size
        return self.form.omega(theta[:s]), self.form.omega(theta[s:])

    def evaluate(self, theta: np.ndarray) -> _Evaluation:
        k, p = self.data.k, self.data.p
        omega_t, omega_c = self.omegas(theta)
        logdet, Ws = 0.0, []
        info, rhs = np.zeros((k * p, k * p)), np.zeros(k * p)
        for b in self.batches:
            S = b.V + np.kron(np.ones((b.m, b.m)), omega_t) + np.kron(np.eye(b.m), omega_c)
            C = np.linalg.cholesky(S)
            logdet += 2.0 * np.log(np.diagonal(C, axis1=1, axis2=2)).sum()
            W = np.linalg.inv(S)
            Ws.append(W)
            info += np.einsum("nia,nij,njb->ab", b.design, W, b.design)
            rhs += np.einsum("nia,nij,nj->a", b.design, W, b.y)
        beta = np.linalg.solve(info, rhs)
        residuals = [b.y - b.design @ beta for b in self.batches]
        quad = sum(float(np.einsum("ni,nij,nj->", r, W, r))
                   for r, W in zip(residuals, Ws, strict=True))
        ll = -0.5 * (logdet + quad + self.data.observations * np.log(2.0 * np.pi))
        if self.reml:
            ll += -0.5 * np.linalg.slogdet(info)[1] + 0.5 * k * p * np.log(2.0 * np.pi)
        return _Evaluation(float(ll), beta, info, Ws, residuals, quad)

    def log_likelihood(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """The log-likelihood at `theta` and its gradient."""
        k = self.data.k
        ev = self.evaluate(theta)
        inverse = np.linalg.inv(ev.information) if self.reml else None
        d_t, d_c = np.zeros((k, k)), np.zeros((k, k))
        for b, W, r in zip(self.batches, ev.W, ev.residuals, strict=True):
            Wr = np.einsum("nij,nj->ni", W, r)
            G = np.einsum("ni,nj->nij", Wr, Wr) - W
            if inverse is not None:
                WX = W @ b.design
                G += np.einsum("nia,ab,njb->nij", WX, inverse, WX)
            blocks = 0.5 * G.reshape(len(b.rows), b.m, k, b.m, k)
            d_t += blocks.sum(axis=(0, 1, 3))
            d_c += np.einsum("ncjcl->jl", blocks)
        s = self.form.size
        grad = np.concatenate([np.einsum("jl,jlm->m", d_t, self.form.jacobian(theta[:s])),
                               np.einsum("jl,jlm->m", d_c, self.form.jacobian(theta[s:]))])
        return ev.log_likelihood, grad

    def bounds(self) -> list[tuple[float, float]]:
        one = omega_bounds(self.form, self.floor, 100.0 * self.spread)
        return one + one

    def maximise(self, start: np.ndarray, fixed: dict[int, float] | None = None,
                 second_start: bool = True) -> tuple[np.ndarray, float]:
        lowered = [*range(self.form.k), *range(self.form.size, self.form.size + self.form.k)]
        return bounded_maximum(self.log_likelihood, start, self.bounds(), fixed,
                               lowered if second_start else ())

    def start(self) -> np.ndarray:
        """Half the spread of the estimates about their mean, beyond their own variance, to
        each level (a diagonal start)."""
        own = self.variances.mean(axis=0)
        half = np.maximum(0.5 * (self.estimates.var(axis=0) - own),
                          (0.05 * self.spread) ** 2)
        one = self.form.vector(np.diag(half), self.floor)
        return np.concatenate([one, one])


@dataclass
class NestedFit:
    """The fitted population: B with intervals, Omega_T and Omega_C, and each level's tau
    with its interval, in the model's space (log where `data.log`)."""

    data: NestedData
    full_omega: bool
    reml: bool
    theta: np.ndarray
    log_likelihood: float
    beta: np.ndarray  # (k, p)
    beta_cov: np.ndarray  # (k p, k p), coefficients column by column, Knapp-Hartung scaled
    omega_test: np.ndarray
    omega_canopy: np.ndarray
    coefficients: dict[tuple[str, str], Interval] = field(default_factory=dict)
    tau_test: dict[str, Interval] = field(default_factory=dict)
    tau_canopy: dict[str, Interval] = field(default_factory=dict)

    @property
    def dof(self) -> int:
        """Degrees of freedom of the coefficients' t intervals: tests less columns."""
        return len(self.data.tests) - self.data.p

    def test_share(self) -> np.ndarray:
        """Per parameter, the share of the between-opening variance that is the test's:
        tau_T^2 / (tau_T^2 + tau_C^2) (NaN where both are 0)."""
        t, c = np.diag(self.omega_test), np.diag(self.omega_canopy)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(t + c > 0.0, t / (t + c), np.nan)


def fit_nested(data: NestedData, full_omega: bool = False, reml: bool = True,
               intervals: bool = True, level: float = LEVEL) -> NestedFit:
    """Maximise the (restricted) likelihood of `data`; with `intervals`, each coefficient's
    t interval and each level's tau's profile-likelihood interval at `level`.  A diagonal
    Omega at each level by default: two full ones hold k (k + 1) parameters, more than a
    campaign of ten tests determines."""
    with one_thread():
        model = NestedModel(data, full_omega, reml)
        theta, ll = model.maximise(model.start())
        ev = model.evaluate(theta)
        k, p = data.k, data.p
        q = ev.quad / max(data.observations - k * p, 1)
        beta_cov = np.linalg.inv(ev.information) * max(1.0, q)
        omega_t, omega_c = model.omegas(theta)
        fit = NestedFit(data, model.form.full, reml, theta, ll,
                        ev.beta.reshape(p, k).T, beta_cov, omega_t, omega_c)
        if not intervals:
            return fit
        t = stats.t.ppf(0.5 + level / 2, fit.dof)
        se = np.sqrt(np.diag(beta_cov)).reshape(p, k).T
        for j, name in enumerate(data.names):
            for a, column in enumerate(data.columns):
                b = float(fit.beta[j, a])
                fit.coefficients[(name, column)] = Interval(b, b - t * se[j, a],
                                                            b + t * se[j, a])

        def maximum(fixed: dict[int, float]) -> float:
            return model.maximise(theta, fixed, second_start=False)[1]

        floor = np.log(model.floor)
        for j, name in enumerate(data.names):
            fit.tau_test[name] = profile_interval(maximum, theta, ll, j, floor[j], level)
            fit.tau_canopy[name] = profile_interval(maximum, theta, ll, model.form.size + j,
                                                    floor[j], level)
        return fit
