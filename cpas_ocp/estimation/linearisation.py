"""The linearisation at a point and what it gives (`Estimator`'s third part): the
covariance of the free parameters, Gauss-Newton estimates and steps, the
information's log-determinant, and chi-square with the constraints' violation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np

from cpas_ocp.estimation import kkt_system
from cpas_ocp.estimation.fit import HESSIANS, Fit
from cpas_ocp.estimation.gauss_newton import gauss_newton_step
from cpas_ocp.estimation.kkt_system import Linearisation
from cpas_ocp.estimation.transcription import Transcription
from cpas_ocp.estimation.uncertainty import (
    Covariance,
    kkt_covariance,
    log_det_information,
)


class Linearisations:
    """Linearisations of one transcribed NLP and the statistics they give."""

    def __init__(self, nlp: Transcription) -> None:
        self.nlp = nlp
        self._hessian_product: ca.Function | None = None  # built on first use

    def covariance(self, fit: Fit, scale_by_residual: bool = False,
                   hessian: str = "gauss-newton") -> Covariance:
        """Covariance of the free parameters at `fit`: the KKT system's parameter block.

        `hessian` is "gauss-newton" (J'J of the weighted residuals) or "exact"
        (the Hessian of the Lagrangian at the fit's multipliers; see
        `uncertainty`).  `scale_by_residual` multiplies it by chi^2/dof, for
        sensor sigmas that are not trusted.
        """
        if hessian not in HESSIANS:
            raise ValueError(f"hessian must be one of {HESSIANS}; got {hessian!r}")
        product = None
        if hessian == "exact":
            fn = self.lagrangian_hessian_product()
            product = lambda Z: np.asarray(  # noqa: E731
                fn.map(Z.shape[1], "serial")(fit.z, fit.multipliers, Z))
        return self.covariance_at(fit.z, scale_by_residual, product)

    def covariance_at(self, z: np.ndarray, scale_by_residual: bool = False,
                      hessian_product: Callable[[np.ndarray], np.ndarray] | None = None
                      ) -> Covariance:
        """Covariance of the free parameters at the decision vector `z` (a fit's, or the
        nominal point of a planned test, where with noise-free data it is the inverse
        Fisher information); `hessian_product` as in `kkt_covariance`."""
        return kkt_covariance(self.linearise(z), self.nlp.param_index, self.nlp.pscale,
                              self.nlp.free, scale_by_residual, hessian_product)

    def gauss_newton_estimate(self, z: np.ndarray, release: Sequence[str] = ()
                              ) -> tuple[dict[str, float], Covariance]:
        """The free parameters after one Gauss-Newton step from `z` (SI), and their covariance
        there; parameters in `release` are treated as unbounded (see `linearise`).

        At the optimum of a model with some parameters held at null values, the
        step's components along them are their linearised estimates (`score_test`).
        """
        lin = self.linearise(z, release)
        cov = kkt_covariance(lin, self.nlp.param_index, self.nlp.pscale, self.nlp.free)
        return self.nlp.free_values(z + gauss_newton_step(lin)), cov

    def information_log_det(self, fit: Fit) -> float:
        """log det of the Gauss-Newton information of every free coordinate at `fit`, in the
        scaled decision vector (`uncertainty.log_det_information`): the volume term of a
        Laplace approximation (`process_intensity`)."""
        return log_det_information(self.linearise(fit.z))

    def gauss_newton_point(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """The end of one full Gauss-Newton step from the decision vector `z` (the linearised
        constraints met there), clipped into the variables' bounds, and the chi-square
        at `z`: both from one linearisation."""
        lin = self.linearise(z)
        step_end = np.clip(z + gauss_newton_step(lin), self.nlp.lbz, self.nlp.ubz)
        return step_end, float(lin.r @ lin.r)

    def lagrangian_hessian_product(self) -> ca.Function:
        """(z, lambda, v) -> H v, H the Hessian of 0.5 |r|^2 + lambda' g in the scaled z
        (forward over reverse mode on the NLP's expression graph; built on first use)."""
        if self._hessian_product is None:
            z, g = self.nlp.z, self.nlp.g
            lam, v = ca.MX.sym("lam", g.numel()), ca.MX.sym("v", z.numel())
            grad = ca.gradient(self.nlp.objective + ca.dot(lam, g), z)
            self._hessian_product = ca.Function("hessian_product", [z, lam, v],
                                                [ca.jtimes(grad, z, v)])
        return self._hessian_product

    def linearise(self, z: np.ndarray, release: Sequence[str] = ()) -> Linearisation:
        """The problem linearised at `z`; the free parameters named in `release` are treated
        as unbounded (a score test's parameters sit on a bound at their null values)."""
        nlp = self.nlp
        idx, nx, n_states = nlp.param_index, nlp.model.nx, nlp.sizes[0]
        pinned = np.flatnonzero(nlp.lbz[:nx] == nlp.ubz[:nx])
        lower, upper = nlp.lbz[idx].copy(), nlp.ubz[idx].copy()
        for name in release:
            i = nlp.free.index(name)
            lower[i], upper[i] = -np.inf, np.inf
        return kkt_system.linearise(nlp.points.residual_jacobian, nlp.points.constraints, z,
                                    nlp.lbg, nlp.ubg, idx, lower, upper,
                                    chain_rows=n_states - nx, dependent=np.arange(nx, n_states),
                                    pinned=pinned)

    def evaluate(self, z: np.ndarray) -> tuple[float, float]:
        """Chi-square at the decision vector `z` and its largest scaled constraint violation
        (the shooting gaps in units of the state scales), from the residuals' and the
        constraints' values alone (`Linearisation.violation`'s figure; NaN where the
        constraints are not finite).  Most points asked about are trials (a descent's,
        a restart's) that are never linearised; where one is, its Jacobians are evaluated
        then, and the values come from them."""
        r = self.nlp.points.residual_value(z)
        return float(r @ r), self.nlp.value_violation(z)
