"""A missing drag law found by sparse regression inside the NLP.

Where no effect in the library, no refinement of one added and no plug-in
written from the residual's signature is confirmed, and the fit is still a
misfit, the missing physics may be a dependence of the drag area on the flow
that no template holds (a porous canopy flattening under load).  `select`
estimates it as a sparse combination of the features of `DragLawTerms`
(logarithmic sensitivities of the drag area to the dynamic pressure, the
density, and the square of the first), the way sequentially thresholded
least squares (SINDy's STLSQ) does, with the NLP as its least-squares step:

1. the model with every feature's term is refitted from the fit (the terms
   at 0) and tested against it by likelihood ratio on K degrees of freedom
   (K features) at level alpha: a single test, made before anything is
   selected, so selection cannot inflate it.  Where it does not pass, no
   term is needed;
2. the term with the smallest |estimate / sigma| (sigma from the refit's
   covariance) is dropped where that ratio lies below the two-sided normal
   quantile at alpha / K (each term kept is then significant at the
   family-wise level over the K), and the rest refitted from there; again
   until every term left passes.  A term with no sigma (on its bound, or
   undetermined) goes first: on `fbcp` flown through a wind shear layer the
   density's term had none, standing in for the wind's change with altitude;
3. the terms left, with their estimates and sigma, are the drag law; their
   likelihood ratio against the fit without them is reported beside the gate.

Dropping one term at a time (backward elimination) rather than every weak one
at once keeps a term whose weakness was only its correlation with another:
the features share the phase's deceleration.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from cpas_ocp.discrepancy.score_test import extended_spec
from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.kkt_system import NonFiniteCurvature
from cpas_ocp.inference.model_comparison import LikelihoodRatio, refit
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.drag_law_terms import FEATURES, DragLawTerms, term_name
from cpas_ocp.precision import with_sigma

# Ipopt's iteration limit of each refit of the selection.
SELECT_MAX_ITER = 150


@dataclass
class TermSelection:
    """The sparse regression at chain step `step`: the gate (every term against none),
    the terms selected with (estimate, sigma), their likelihood ratio against the fit
    without them, what each round dropped, and why it stopped where it found nothing."""

    step: int
    gate: LikelihoodRatio | None = None
    selected: dict[str, tuple[float, float]] = field(default_factory=dict)
    lr: LikelihoodRatio | None = None
    dropped: list[str] = field(default_factory=list)
    note: str = ""
    spec: ModelSpec | None = field(default=None, repr=False)
    refitted: tuple[Estimator, Fit] | None = field(default=None, repr=False)

    @property
    def found(self) -> bool:
        return bool(self.selected) and self.refitted is not None and self.lr is not None

    def __str__(self) -> str:
        """One line: the gate, what was dropped and kept, with estimates and sigma."""
        head = f"step {self.step}: drag-law terms ({', '.join(FEATURES)})"
        if self.gate is None:
            return f"{head}: {self.note}"
        parts = [f"every term against none: {self.gate}"]
        if self.dropped:
            parts.append("dropped " + ", ".join(self.dropped))
        if self.selected and self.lr is not None:  # a record read back has no refit
            terms = ", ".join(f"{n} = {with_sigma(v, s)}" for n, (v, s) in self.selected.items())
            parts.append(f"kept {terms}; {self.lr}")
        if self.note:
            parts.append(self.note)
        return f"{head}: " + "; ".join(parts)

    def as_dict(self) -> dict:
        """The selection as JSON holds it (the refit's spec and fit left out)."""
        return {"step": self.step, "features": list(FEATURES),
                "gate": None if self.gate is None else self.gate.as_dict(),
                "selected": {n: {"estimate": v, "sigma": s}
                             for n, (v, s) in self.selected.items()},
                "likelihood_ratio": None if self.lr is None else self.lr.as_dict(),
                "dropped": self.dropped, "note": self.note}

    @classmethod
    def from_dict(cls, data: dict) -> TermSelection:
        return cls(data["step"], LikelihoodRatio.from_dict(data["gate"]),
                   {n: (v["estimate"], v["sigma"]) for n, v in data["selected"].items()},
                   LikelihoodRatio.from_dict(data["likelihood_ratio"]), list(data["dropped"]),
                   data["note"])


def select(fit: Fit, spec: ModelSpec, step: int, alpha: float, progress: bool = False
           ) -> TermSelection:
    """The sparse drag law of `fit` (of `spec`, chain step `step`): see the module
    docstring."""
    out = TermSelection(step)
    q = fit.quantities()
    law = DragLawTerms(reference_pa=float(np.median(q["dynamic_pressure"])),
                       reference_density=float(np.median(q["density"])))
    try:
        full = extended_spec(fit, spec, law)
        est, current = refit(fit, full, values=law.null_values(fit.test), progress=progress,
                             max_iter=SELECT_MAX_ITER)
    except (SolverFailure, InputError) as exc:
        out.note = f"the refit with every term did not converge ({exc})"
        return out
    k = len(FEATURES)
    out.gate = LikelihoodRatio(fit.chi_square - current.chi_square, k)
    if out.gate.p_value >= alpha:
        out.note = "no term is needed"
        return out
    threshold = float(norm.isf(alpha / (2.0 * k)))
    terms = list(FEATURES)
    while True:
        try:
            std = est.covariance(current).std
        except NonFiniteCurvature:
            out.note = f"the covariance with terms {', '.join(terms)} is not finite"
            return out
        # A term with no sigma (on its bound, or undetermined: `Covariance.std`) is tested
        # by nothing, and goes first.
        z = {t: abs(current.parameters[term_name(t)]) / std[term_name(t)]
             if term_name(t) in std else 0.0 for t in terms}
        weakest = min(terms, key=lambda t: z[t])
        if z[weakest] >= threshold:
            break
        out.dropped.append(f"{weakest} (no sigma)" if term_name(weakest) not in std
                           else f"{weakest} (|z| {z[weakest]:.1f})")
        terms.remove(weakest)
        if not terms:
            out.note = f"no term passes |z| >= {threshold:.2f} (alpha / {k}, two-sided)"
            return out
        smaller = dataclasses.replace(full, effects=tuple(
            dataclasses.replace(e, terms=tuple(terms)) if isinstance(e, DragLawTerms) else e
            for e in full.effects))
        try:
            est, current = refit(current, smaller, progress=progress,
                                 max_iter=SELECT_MAX_ITER)
        except (SolverFailure, InputError) as exc:
            out.note = f"the refit with terms {', '.join(terms)} did not converge ({exc})"
            return out
        full = smaller
    out.selected = {term_name(t): (current.parameters[term_name(t)], std[term_name(t)])
                    for t in terms}
    out.lr = LikelihoodRatio(fit.chi_square - current.chi_square, len(terms))
    out.spec, out.refitted = full, (est, current)
    if not math.isfinite(out.lr.statistic):
        out.note = "the likelihood ratio is not a number"
        out.refitted = None
    return out
