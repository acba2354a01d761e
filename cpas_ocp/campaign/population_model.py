"""A population of canopies: between-test spread estimated with each test's own uncertainty.

Each canopy opening i of a campaign (one canopy of one test, in one stage) gives an
estimate y_i of its k parameters with the covariance V_i of its fit.  The
two-stage population model (multivariate random-effects meta-regression, the
model of nonlinear mixed-effects software applied to the tests' estimates) is

    y_i = theta_i + e_i,      e_i ~ N(0, V_i)       (each test's estimation noise)
    theta_i = B x_i + eta_i,  eta_i ~ N(0, Omega)   (the real test-to-test spread)

with x_i the covariates of opening i (a leading 1, then any columns of the test
table: configuration, line length, cluster size, forebody) and B the k x p
coefficients: the population mean mu = B x and the covariates' effects.
Positive parameters (drag areas, Ck, fill constants, expopen) are modelled in
log space, where a multiplicative spread is normal and V_i is the fit's
covariance divided by the estimates (the delta method): exp(mu) is then the
population median and Omega's diagonal the squared coefficients of variation.

Given Omega, B is the generalised least-squares estimate with weights
W_i = (Omega + V_i)^-1.  Omega = D R D (D the between-test standard deviations
tau, R a correlation matrix through partial correlations, or the identity for
a diagonal Omega) is estimated by maximising the restricted likelihood
(REML: the likelihood of the residuals' contrasts, which does not bias tau low
by the p degrees of freedom the mean takes; Patterson and Thompson 1971), or
the full likelihood where models with different means are compared.

Intervals:
- each coefficient of B: (sum_i X_i' W_i X_i)^-1 at the REML Omega, its
  variance multiplied by max(1, q), q the weighted residual sum of squares per
  degree of freedom, and Student's t with n - p degrees of freedom
  (Knapp and Hartung 2003, in the Hartung-Knapp-Sidik-Jonkman form that
  does not let q shrink the interval), because with 10 to 30 tests the normal
  quantile at a plug-in Omega is too narrow;
- each tau_j: the profile restricted likelihood, 2 (l_max - l_p(tau_j)) <= the
  chi-square(1) quantile, the other coordinates re-estimated at each tau_j;
  where tau_j = 0 lies inside, the interval starts at 0.

Per opening, the shrunken estimate theta~_i = B x_i + Omega W_i r_i (the best
linear unbiased predictor, r_i = y_i - B x_i) with covariance Omega - Omega W_i
Omega, and its pull: the Mahalanobis distance r_i' W_i r_i against chi-square(k),
and r_ij / sqrt(Omega_jj + V_i,jj) per parameter.  The share of the observed
spread that is real is Higgins and Thompson's I^2 = tau^2 / (tau^2 + v~), v~ the
typical within-test variance (n - 1) sum w / ((sum w)^2 - sum w^2), w = 1/V_i,jj.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from cpas_ocp.blas_threads import one_thread
from cpas_ocp.errors import SolverFailure

# A between-test standard deviation this small against the estimates' own spread is
# treated as zero (the optimiser's floor: the likelihood is flat below it).
TAU_FLOOR = 1e-6
# Partial correlations are kept within tanh(+-CORRELATION_BOUND) = +-0.995.
CORRELATION_BOUND = 3.0
LEVEL = 0.95
# Largest projected gradient of the log-likelihood (per unit of log tau or partial
# correlation's parameter) at which a maximisation L-BFGS-B did not call converged is
# accepted: far below the statistical scale, where an interval's edge lies 1.92 down.
STATIONARY = 1e-2


class PopulationInputError(ValueError):
    """The estimates cannot carry a population fit (too few openings, a covariate with one
    level, a covariance that is not positive definite); the message says which."""


@dataclass(frozen=True)
class PopulationData:
    """The estimates of one population, in the space the model is fitted in.

    `y` (n, k): each opening's estimates (log of the value where `log[j]`);
    `V` (n, k, k): their covariance in the same space; `X` (n, p): the design,
    `columns` naming its columns (the first the intercept); `openings` names
    each row (test and canopy).
    """

    names: tuple[str, ...]
    openings: tuple[str, ...]
    y: np.ndarray
    V: np.ndarray
    X: np.ndarray
    columns: tuple[str, ...]
    log: tuple[bool, ...]

    def __post_init__(self) -> None:
        n, k = self.y.shape
        p = self.X.shape[1]
        if self.V.shape != (n, k, k) or self.X.shape[0] != n:
            raise PopulationInputError(f"shapes do not agree: y {self.y.shape}, V "
                                       f"{self.V.shape}, X {self.X.shape}")
        if n < p + 2:
            raise PopulationInputError(
                f"{n} openings for {p} mean coefficient(s) per parameter: a population "
                f"needs at least {p + 2}")
        if np.linalg.matrix_rank(self.X) < p:
            raise PopulationInputError(
                f"the covariates ({', '.join(self.columns[1:])}) do not vary independently "
                "over the openings (a covariate with one level, or two that are the same)")
        if not (np.isfinite(self.y).all() and np.isfinite(self.V).all()):
            raise PopulationInputError("an estimate or its covariance is not finite")
        eig = np.linalg.eigvalsh(0.5 * (self.V + np.transpose(self.V, (0, 2, 1))))
        bad = np.flatnonzero(eig.min(axis=1) <= 0.0)
        if bad.size:
            raise PopulationInputError(
                f"{self.openings[bad[0]]}: the covariance of its estimates is not positive "
                f"definite (smallest eigenvalue {eig[bad[0]].min():.3g})")

    @property
    def n(self) -> int:
        return self.y.shape[0]

    @property
    def k(self) -> int:
        return self.y.shape[1]

    @property
    def p(self) -> int:
        return self.X.shape[1]

    def subset(self, rows: np.ndarray, keep_columns: Sequence[int] | None = None
               ) -> PopulationData:
        """The openings `rows` (a boolean mask or indices), with the design's columns
        `keep_columns` (all by default)."""
        cols = list(range(self.p)) if keep_columns is None else list(keep_columns)
        idx = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows)
        return PopulationData(self.names, tuple(self.openings[i] for i in idx), self.y[idx],
                              self.V[idx], self.X[np.ix_(idx, cols)],
                              tuple(self.columns[c] for c in cols), self.log)


def correlation_factor(partial: np.ndarray, k: int) -> np.ndarray:
    """The lower-triangular Cholesky factor L of the k x k correlation matrix of the partial
    correlations `partial` (k(k-1)/2 values in (-1, 1), the lower triangle row by row), as
    in the LKJ construction, so every vector gives a valid correlation matrix: in row i,
    L_ij = z_ij sqrt(prod_{j'<j} (1 - z_ij'^2)) and L_ii = sqrt(prod_{j<i} (1 - z_ij^2))."""
    L = np.zeros((k, k))
    L[0, 0] = 1.0
    it = iter(partial)
    for i in range(1, k):
        remaining = 1.0
        for j in range(i):
            z = next(it)
            L[i, j] = z * np.sqrt(remaining)
            remaining *= 1.0 - z * z
        L[i, i] = np.sqrt(max(remaining, 0.0))
    return L


def correlation_matrix(partial: np.ndarray, k: int) -> np.ndarray:
    """The k x k correlation matrix L L' of `correlation_factor`."""
    L = correlation_factor(partial, k)
    return L @ L.T


def _partial_correlations(R: np.ndarray) -> np.ndarray:
    """The inverse of `correlation_matrix`: the partial correlations of R's Cholesky
    factor, row by row."""
    L = np.linalg.cholesky(R)
    out = []
    for i in range(1, R.shape[0]):
        remaining = 1.0
        for j in range(i):
            out.append(L[i, j] / np.sqrt(remaining))
            remaining -= L[i, j] ** 2
    return np.clip(np.array(out), -0.99, 0.99)


@dataclass(frozen=True)
class OmegaForm:
    """How Omega is parametrised: tau (k standard deviations) and, for a full Omega, the
    k(k-1)/2 partial correlations, as one vector: log tau, then atanh of each."""

    k: int
    full: bool

    @property
    def size(self) -> int:
        return self.k + (self.k * (self.k - 1) // 2 if self.full else 0)

    def omega(self, theta: np.ndarray) -> np.ndarray:
        tau = np.exp(theta[: self.k])
        if not self.full or self.k == 1:
            return np.diag(tau**2)
        R = correlation_matrix(np.tanh(theta[self.k:]), self.k)
        return R * np.outer(tau, tau)

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """d(Omega)/d(theta), (k, k, size).  For log tau_m: Omega_ab (delta_am + delta_bm).
        For the partial correlation z = tanh(u) at row i, column m of the factor L
        (`correlation_factor`): dL_im/du = (1 - z^2) sqrt(prod_{j<m} (1 - z_ij^2)), and
        dL_ij/du = -z L_ij for m < j <= i; then dOmega = D (dL L' + L dL') D."""
        k = self.k
        omega = self.omega(theta)
        out = np.zeros((k, k, self.size))
        for m in range(k):
            out[m, :, m] += omega[m, :]
            out[:, m, m] += omega[:, m]
        if not self.full or k == 1:
            return out
        tau = np.exp(theta[:k])
        z = np.tanh(theta[k:])
        L = correlation_factor(z, k)
        scale = np.outer(tau, tau)
        index = k
        for i in range(1, k):
            remaining = 1.0
            for m in range(i):
                zm = z[index - k]
                dL = np.zeros((k, k))
                dL[i, m] = (1.0 - zm * zm) * np.sqrt(remaining)
                dL[i, m + 1:i + 1] = -zm * L[i, m + 1:i + 1]
                out[:, :, index] = (dL @ L.T + L @ dL.T) * scale
                remaining *= 1.0 - zm * zm
                index += 1
        return out

    def vector(self, omega: np.ndarray, floor: np.ndarray) -> np.ndarray:
        tau = np.maximum(np.sqrt(np.maximum(np.diag(omega), 0.0)), floor)
        theta = list(np.log(tau))
        if self.full and self.k > 1:
            R = omega / np.outer(tau, tau)
            R = 0.5 * (R + R.T)
            np.fill_diagonal(R, 1.0)
            w, U = np.linalg.eigh(R)
            R = (U * np.maximum(w, 1e-3)) @ U.T
            d = np.sqrt(np.diag(R))
            theta += list(np.arctanh(_partial_correlations(R / np.outer(d, d))))
        return np.array(theta)


@dataclass(frozen=True)
class _Evaluation:
    """The likelihood at one Omega, with what the estimates need."""

    log_likelihood: float  # ML or REML, as asked
    beta: np.ndarray  # (k, p)
    information: np.ndarray  # (k p, k p): sum X_i' W_i X_i
    W: np.ndarray  # (n, k, k)
    residuals: np.ndarray  # (n, k)


def evaluate(data: PopulationData, omega: np.ndarray, reml: bool) -> _Evaluation:
    """The (restricted) log-likelihood of `data` at `omega`, B at its GLS estimate."""
    n, k, p = data.n, data.k, data.p
    S = omega[None] + data.V
    C = np.linalg.cholesky(S)
    logdet = 2.0 * np.log(np.diagonal(C, axis1=1, axis2=2)).sum()
    W = np.linalg.inv(S)
    # Design of opening i: kron(I_k, x_i'), so information[(j,a),(l,b)] = sum x_ia W_ijl x_ib.
    info = np.einsum("ia,ijl,ib->jalb", data.X, W, data.X).reshape(k * p, k * p)
    rhs = np.einsum("ia,ijl,il->ja", data.X, W, data.y).reshape(k * p)
    beta = np.linalg.solve(info, rhs).reshape(k, p)
    r = data.y - data.X @ beta.T
    quad = float(np.einsum("ij,ijl,il->", r, W, r))
    ll = -0.5 * (logdet + quad + n * k * np.log(2.0 * np.pi))
    if reml:
        _, logdet_info = np.linalg.slogdet(info)
        ll += -0.5 * logdet_info + 0.5 * k * p * np.log(2.0 * np.pi)
    return _Evaluation(float(ll), beta, info, W, r)


def omega_gradient(data: PopulationData, ev: _Evaluation, reml: bool) -> np.ndarray:
    """d(log-likelihood)/d(Omega) (k x k, symmetric) at the evaluation `ev`, B at its GLS
    estimate (its own derivative is zero there):

        1/2 sum_i [ W_i r_i r_i' W_i - W_i  (+ W_i X_i A^-1 X_i' W_i with REML) ],

    A = sum_i X_i' W_i X_i the information `ev.information`."""
    k, p = data.k, data.p
    Wr = np.einsum("ijl,il->ij", ev.W, ev.residuals)
    grad = np.einsum("ij,il->jl", Wr, Wr) - ev.W.sum(axis=0)
    if reml:
        inverse = np.linalg.inv(ev.information).reshape(k, p, k, p)
        M = np.einsum("ia,jalb,ib->ijl", data.X, inverse, data.X)  # X_i A^-1 X_i'
        grad += np.einsum("ijm,imn,inl->jl", ev.W, M, ev.W)
    return 0.5 * grad


def search_scale(y: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """Per parameter, the larger of the estimates' spread (`y`, one row per opening) and
    their typical standard deviation (`variances`, each estimate's, the same shape): the
    scale of tau's search range."""
    return np.maximum(y.std(axis=0), np.sqrt(np.median(variances, axis=0)))


def _spread(data: PopulationData) -> np.ndarray:
    """`search_scale` of `data`'s estimates."""
    return search_scale(data.y, np.diagonal(data.V, axis1=1, axis2=2))


def _floor(data: PopulationData) -> np.ndarray:
    """Per parameter, the tau below which the likelihood is flat: TAU_FLOOR times
    `_spread`."""
    return TAU_FLOOR * np.maximum(_spread(data), 1e-12)


def _moment_start(data: PopulationData) -> np.ndarray:
    """A start for Omega: the residuals' covariance from an ordinary least-squares mean
    less the mean within-test covariance, its eigenvalues held positive."""
    coef, *_ = np.linalg.lstsq(data.X, data.y, rcond=None)
    r = data.y - data.X @ coef
    S = r.T @ r / max(data.n - data.p, 1) - data.V.mean(axis=0)
    w, U = np.linalg.eigh(0.5 * (S + S.T))
    scale = np.maximum(data.y.std(axis=0), 1e-12)
    w = np.maximum(w, (0.05 * scale.min()) ** 2)
    return (U * w) @ U.T


# A log-likelihood of Omega's parameters: its value and gradient (raises LinAlgError where
# a covariance is not positive definite).
LogLikelihood = Callable[[np.ndarray], tuple[float, np.ndarray]]


def bounded_maximum(loglik: LogLikelihood, start: np.ndarray,
                    bounds: Sequence[tuple[float, float]], fixed: dict[int, float] | None = None,
                    lowered: Sequence[int] = ()) -> tuple[np.ndarray, float]:
    """The parameters maximising `loglik` within `bounds`, the coordinates in `fixed` held,
    and the maximum, by L-BFGS-B; where `lowered` names coordinates (log standard
    deviations), also from a second start with each of them ln 10 lower (the likelihood
    may have a mode on the boundary).  SolverFailure where the maximisation ended neither
    converged nor stationary (`_check_converged`)."""
    fixed = fixed or {}
    size = len(start)
    free = [i for i in range(size) if i not in fixed]
    free_bounds = [bounds[i] for i in free]
    lower, upper = np.array(free_bounds).T if free else (np.empty(0), np.empty(0))

    def full(x: np.ndarray) -> np.ndarray:
        theta = np.empty(size)
        theta[free] = x
        for i, v in fixed.items():
            theta[i] = v
        return theta

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        try:
            value, grad = loglik(full(x))
        except np.linalg.LinAlgError:
            return 1e30, np.zeros(len(x))
        return -value, -grad[free]

    x0 = np.clip(np.asarray(start, dtype=float)[free], lower, upper)
    if not free:
        return full(x0), -objective(x0)[0]
    best = optimize.minimize(objective, x0, jac=True, method="L-BFGS-B", bounds=free_bounds)
    down = [j for j, i in enumerate(free) if i in set(lowered)]
    if down:
        x1 = x0.copy()
        x1[down] -= np.log(10.0)
        other = optimize.minimize(objective, np.clip(x1, lower, upper), jac=True,
                                  method="L-BFGS-B", bounds=free_bounds)
        if other.fun < best.fun:
            best = other
    _check_converged(best, free_bounds)
    return full(best.x), -float(best.fun)


def profile_interval(maximum: Callable[[dict[int, float]], float], theta: np.ndarray,
                     log_likelihood: float, j: int, floor: float, level: float = LEVEL
                     ) -> Interval:
    """The profile-likelihood interval of the standard deviation whose log is coordinate
    `j` of `theta` (the maximum, of value `log_likelihood`): the values whose profile,
    `maximum({j: value})` with every other coordinate re-estimated, lies within
    chi-square(1, level) / 2 of the maximum.  `floor` (log) is where the likelihood is
    flat; an estimate there is 0 and the interval starts at 0."""
    limit = stats.chi2.ppf(level, 1) / 2.0
    at_floor = theta[j] <= floor + 1e-6

    def drop(log_sd: float) -> float:
        return log_likelihood - maximum({j: log_sd}) - limit

    lower = 0.0
    if not at_floor and drop(floor) > 0.0:
        lower = float(np.exp(optimize.brentq(drop, floor, theta[j], xtol=1e-4)))
    hi = theta[j] + np.log(2.0)
    for _ in range(40):
        if drop(hi) > 0.0:
            break
        hi += np.log(2.0)
    upper = float(np.exp(optimize.brentq(drop, theta[j], hi, xtol=1e-4)))
    return Interval(0.0 if at_floor else float(np.exp(theta[j])), lower, upper)


def omega_bounds(form: OmegaForm, floor: np.ndarray, ceiling: np.ndarray
                 ) -> list[tuple[float, float]]:
    """Bounds of Omega's parameters: log tau within [log floor, log ceiling], each partial
    correlation's atanh within +-CORRELATION_BOUND."""
    return [(float(np.log(floor[i])), float(np.log(ceiling[i]))) if i < form.k
            else (-CORRELATION_BOUND, CORRELATION_BOUND) for i in range(form.size)]


def _maximise(data: PopulationData, form: OmegaForm, reml: bool, start: np.ndarray,
              fixed: dict[int, float] | None = None, second_start: bool = True
              ) -> tuple[np.ndarray, float]:
    """The vector theta (see OmegaForm) maximising the likelihood, coordinates in `fixed`
    held; and the maximum.  With `second_start`, also from every free tau at a tenth of
    `start`'s (the likelihood may have a mode on the boundary)."""

    def loglik(theta: np.ndarray) -> tuple[float, np.ndarray]:
        ev = evaluate(data, form.omega(theta), reml)
        grad = np.einsum("jl,jlm->m", omega_gradient(data, ev, reml), form.jacobian(theta))
        return ev.log_likelihood, grad

    bounds = omega_bounds(form, _floor(data), 100.0 * _spread(data))
    return bounded_maximum(loglik, start, bounds, fixed,
                           range(form.k) if second_start else ())


def _check_converged(result: optimize.OptimizeResult, bounds: list[tuple[float, float]]
                     ) -> None:
    """Raise SolverFailure (L-BFGS-B's message and iterations) where the likelihood's
    maximisation ended neither converged nor at a point whose projected gradient is
    below STATIONARY (L-BFGS-B's line search can give up at the optimum itself)."""
    if result.success:
        return
    lower, upper = np.array(bounds).T
    g = np.asarray(result.jac, dtype=float)
    x = np.asarray(result.x, dtype=float)
    held = ((x <= lower) & (g > 0.0)) | ((x >= upper) & (g < 0.0))
    if np.all(np.isfinite(g)) and np.max(np.abs(np.where(held, 0.0, g))) < STATIONARY:
        return
    raise SolverFailure(f"population likelihood: {result.message}", int(result.nit))


@dataclass(frozen=True)
class Interval:
    """An estimate with its interval at `LEVEL`."""

    value: float
    lower: float
    upper: float

    def covers(self, x: float) -> bool:
        return self.lower <= x <= self.upper


@dataclass
class PopulationFit:
    """The fitted population: B with intervals, Omega, tau with intervals, per-opening
    shrunken estimates and pulls, I^2.  All in the model's space (log where `data.log`)."""

    data: PopulationData
    full_omega: bool
    reml: bool
    theta: np.ndarray
    log_likelihood: float
    beta: np.ndarray  # (k, p)
    beta_cov: np.ndarray  # (k p, k p), Knapp-Hartung scaled
    omega: np.ndarray
    q: float  # weighted residual sum of squares per degree of freedom
    coefficients: dict[tuple[str, str], Interval] = field(default_factory=dict)
    tau: dict[str, Interval] = field(default_factory=dict)

    @property
    def dof(self) -> int:
        """Degrees of freedom of the coefficients' t intervals: openings less columns."""
        return self.data.n - self.data.p

    @property
    def parameters(self) -> int:
        """Free parameters of the model: B's coefficients and Omega's."""
        return self.beta.size + OmegaForm(self.data.k, self.full_omega).size

    def shrunken(self) -> tuple[np.ndarray, np.ndarray]:
        """Each opening's best linear unbiased predictor of theta_i (n, k) and its
        covariance (n, k, k)."""
        ev = evaluate(self.data, self.omega, self.reml)
        mean = self.data.X @ self.beta.T
        gain = self.omega[None] @ ev.W
        theta = mean + np.einsum("ijl,il->ij", gain, ev.residuals)
        cov = self.omega[None] - gain @ self.omega[None]
        return theta, cov

    def pulls(self) -> tuple[np.ndarray, np.ndarray]:
        """Per opening, the standardised residual of each parameter (n, k) and the p-value
        of its Mahalanobis distance against chi-square(k) (n,)."""
        ev = evaluate(self.data, self.omega, self.reml)
        S = self.omega[None] + self.data.V
        z = ev.residuals / np.sqrt(np.diagonal(S, axis1=1, axis2=2))
        d2 = np.einsum("ij,ijl,il->i", ev.residuals, ev.W, ev.residuals)
        return z, stats.chi2.sf(d2, self.data.k)

    def i_squared(self) -> np.ndarray:
        """Per parameter, the share of the observed spread that is real (Higgins and
        Thompson's I^2)."""
        v = np.diagonal(self.data.V, axis1=1, axis2=2)
        w = 1.0 / v
        typical = (self.data.n - 1) * w.sum(0) / (w.sum(0) ** 2 - (w**2).sum(0))
        tau2 = np.diag(self.omega)
        return tau2 / (tau2 + typical)

    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.diag(self.omega))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.omega / np.outer(d, d)


def fit_population(data: PopulationData, full_omega: bool = True, reml: bool = True,
                   intervals: bool = True, level: float = LEVEL, tau_intervals: bool = True,
                   start: np.ndarray | None = None) -> PopulationFit:
    """Maximise the (restricted) likelihood of `data`; with `intervals`, the coefficients'
    t intervals and, with `tau_intervals` too, each tau's profile-likelihood interval at
    `level` (a few profile fits per parameter: the costly part).  `start`: Omega's
    parameters (`OmegaForm`) to start from, one start only; by default the moment
    estimate and a second start with every tau a tenth of it.

    BLAS runs on one thread here: the matrices are a few rows wide, and with L-BFGS-B's
    vector operations on a pool of threads `cpas-ocp population` of a campaign of 20
    tests took 30 s against 6.7 s on one (2 cores busy with other work)."""
    with one_thread():
        return _fit_population(data, full_omega, reml, intervals, level, tau_intervals,
                               start)



def _fit_population(data: PopulationData, full_omega: bool, reml: bool, intervals: bool,
                    level: float, tau_intervals: bool, start: np.ndarray | None
                    ) -> PopulationFit:
    form = OmegaForm(data.k, full_omega and data.k > 1)
    if start is None:
        theta, ll = _maximise(data, form, reml, form.vector(_moment_start(data), _floor(data)))
    else:
        theta, ll = _maximise(data, form, reml, start, second_start=False)
    omega = form.omega(theta)
    ev = evaluate(data, omega, reml)
    dof_q = data.n * data.k - data.p * data.k
    q = float(np.einsum("ij,ijl,il->", ev.residuals, ev.W, ev.residuals)) / max(dof_q, 1)
    beta_cov = np.linalg.inv(ev.information) * max(1.0, q)
    fit = PopulationFit(data, form.full, reml, theta, ll, ev.beta, beta_cov, omega, q)
    if intervals:
        t = stats.t.ppf(0.5 + level / 2, fit.dof)
        se = np.sqrt(np.diag(beta_cov)).reshape(data.k, data.p)
        for j, name in enumerate(data.names):
            for a, column in enumerate(data.columns):
                b = float(ev.beta[j, a])
                fit.coefficients[(name, column)] = Interval(b, b - t * se[j, a],
                                                            b + t * se[j, a])
            if tau_intervals:
                fit.tau[name] = tau_interval(fit, j, level)
    return fit


def tau_interval(fit: PopulationFit, j: int, level: float = LEVEL) -> Interval:
    """The profile-likelihood interval of the between-test standard deviation of
    parameter `j`: the taus whose profile lies within chi-square(1, level) / 2 of the
    maximum."""
    data = fit.data
    form = OmegaForm(data.k, fit.full_omega)

    def maximum(fixed: dict[int, float]) -> float:
        return _maximise(data, form, fit.reml, fit.theta, fixed, second_start=False)[1]

    return profile_interval(maximum, fit.theta, fit.log_likelihood, j,
                            float(np.log(_floor(data)[j])), level)


@dataclass(frozen=True)
class GroupingTest:
    """Pooled against separate populations for the levels of one covariate.

    `statistic` = 2 (sum of the separate fits' maximum log-likelihoods - the pooled
    one's), full likelihood, with `dof` more parameters apart than pooled.  Its
    chi-square(dof) law holds only for many openings per parameter: with 20 openings of
    5 parameters and a full Omega (20 more parameters apart) it rejected a true pooling
    in 20 % of 50 simulated campaigns at a level of 5 %.  So it is Bartlett-adjusted by a
    parametric bootstrap (Rocke 1989): `bootstrap` campaigns drawn from the pooled fit
    give the statistic's mean under pooling, `bartlett` = that mean / dof, and the
    p-value is chi-square(dof)'s at statistic / bartlett.  `separate` when the p-value
    is below `alpha`.  `shift` holds the level's effect on each parameter's mean (the
    second level against the first, in the model's space) with its interval, from the
    pooled Omega with the level as a covariate."""

    covariate: str
    levels: tuple[str, ...]
    statistic: float
    dof: int
    p_value: float
    alpha: float
    shift: dict[str, Interval]
    bartlett: float = 1.0
    bootstrap: int = 0

    @property
    def separate(self) -> bool:
        return self.p_value < self.alpha


# Campaigns drawn from the pooled fit to Bartlett-adjust a grouping test's statistic.
BOOTSTRAP = 40


def _split_statistic(data: PopulationData, labels: np.ndarray, levels: tuple[str, ...],
                     full_omega: bool, one_start: bool = False
                     ) -> tuple[float, list[PopulationFit]]:
    """2 (separate - pooled) maximum log-likelihood, and the fits (pooled first, then one
    per level); with `one_start`, each fit from its own moment estimate only (a bootstrap
    campaign started from the data's estimates instead stalled in a poorer optimum in 2
    of 20 campaigns and dragged the adjustment below 1)."""
    parts = [data, *(data.subset(labels == level) for level in levels)]
    form = OmegaForm(data.k, full_omega and data.k > 1)
    fits = [fit_population(part, full_omega, reml=False, intervals=False,
                           start=form.vector(_moment_start(part), _floor(part))
                           if one_start else None) for part in parts]
    separate = sum(f.log_likelihood for f in fits[1:])
    return max(2.0 * (separate - fits[0].log_likelihood), 0.0), fits


def grouping_test(data: PopulationData, labels: Sequence[str], covariate: str,
                  full_omega: bool = True, alpha: float = 0.05, bootstrap: int = BOOTSTRAP,
                  seed: int = 0) -> GroupingTest:
    """Test whether the openings labelled by `labels` (one label per opening, two or more
    levels) share one population (one mean and one Omega) or need one each; the
    statistic Bartlett-adjusted by `bootstrap` campaigns drawn from the pooled fit with
    the seed `seed` (0: the chi-square law as it is)."""
    levels = tuple(sorted(set(labels)))
    if len(levels) < 2:
        raise PopulationInputError(f"{covariate}: one level ({levels[0]}) over the "
                                   "openings; grouping needs two or more")
    labels_arr = np.asarray(labels)
    form = OmegaForm(data.k, full_omega and data.k > 1)
    dof = (len(levels) - 1) * (data.p * data.k + form.size)
    statistic, fits = _split_statistic(data, labels_arr, levels, full_omega)
    bartlett = 1.0
    if bootstrap > 0:
        rng = np.random.default_rng(seed)
        pooled = fits[0]
        root = np.linalg.cholesky(pooled.omega[None] + data.V)
        mean = data.X @ pooled.beta.T
        draws = [_split_statistic(dataclasses.replace(
                     data, y=mean + np.einsum("ijl,il->ij", root,
                                              rng.standard_normal((data.n, data.k)))),
                     labels_arr, levels, full_omega, one_start=True)[0]
                 for _ in range(bootstrap)]
        bartlett = max(float(np.mean(draws)) / dof, 1e-6)
    dummies = np.column_stack([(labels_arr == level).astype(float) for level in levels[1:]])
    shifted = PopulationData(data.names, data.openings, data.y, data.V,
                             np.column_stack([data.X, dummies]),
                             data.columns + tuple(f"{covariate}={lv}" for lv in levels[1:]),
                             data.log)
    with_shift = fit_population(shifted, full_omega, reml=True, tau_intervals=False)
    column = f"{covariate}={levels[1]}"
    shift = {name: with_shift.coefficients[(name, column)] for name in data.names}
    return GroupingTest(covariate, levels, statistic, dof,
                        float(stats.chi2.sf(statistic / bartlett, dof)), alpha, shift,
                        bartlett, bootstrap)
