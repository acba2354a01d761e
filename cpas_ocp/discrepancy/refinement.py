"""Refinements of an effect in the model: a structural constant freed, tested by likelihood ratio.

An effect can be right in kind and wrong in form.  On `drogue` flown with an
added mass that grows as D^6 through the fill, the library's D^3 law removes
most of the excess chi-square and leaves the inflation windows off the noise:
the air mass is there, but it gathers later in the fill than the law says.
A physicist would free the constant the law fixes (the exponent) and ask
whether the data want another value.  Each effect says which of its constants
can be freed (`Effect.refinements`): the refined effect is the same physics
with the constant as a parameter, equal to the original at the refinement's
null values, so the model with the original is nested in the refined one.

`refine` refits the model with each refinement of the named effects, from the
model's own fit (the freed constants at their null values, and at the other
starts the refinement names: the lowest refit kept), and tests
each by its likelihood ratio, chi-square on the number of constants freed
(their nulls lie inside their bounds: two-sided), at the family-wise level
alpha / m over the m refinements tried together.  A refinement whose ratio
does not pass leaves the effect as it is: where the library's law is the
truth, the freed exponent's ratio is chi-square on 1 degree of freedom, and
one in 1 / alpha such fits keeps it at level alpha.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.inference.model_comparison import LikelihoodRatio, refit
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.base import Refinement

# Ipopt's iteration limit for a refinement's refit (from the fit it refines).
REFINE_MAX_ITER = 150


@dataclass
class RefinementTrial:
    """One refinement of `effect` tried at chain step `step`: what it changed, its
    likelihood ratio against the effect as it was (None where the refit failed, with
    `note` saying how), its freed constants' estimates, and whether it passed the
    family-wise level over the `tried` refinements tried with it."""

    step: int
    effect: str
    change: str
    tried: int
    lr: LikelihoodRatio | None = None
    estimates: dict[str, float] = field(default_factory=dict)
    note: str = ""
    kept: bool = False
    spec: ModelSpec | None = field(default=None, repr=False)
    refitted: tuple[Estimator, Fit] | None = field(default=None, repr=False)

    def __str__(self) -> str:
        """One line: the effect, what was freed, and what the test found."""
        if self.lr is None:
            found = self.note
        else:
            found = (f"{self.lr} ({'kept' if self.kept else 'not kept'} over {self.tried} "
                     f"refinement(s) tried); {_values_text(self.estimates)}")
        return f"step {self.step}: {self.effect} with {self.change}: {found}"

    def as_dict(self) -> dict:
        """The trial as JSON holds it (the refit's spec and fit left out)."""
        return {"step": self.step, "effect": self.effect, "change": self.change,
                "tried": self.tried, "kept": self.kept, "note": self.note,
                "estimates": self.estimates,
                "lr": None if self.lr is None else self.lr.as_dict()}

    @classmethod
    def from_dict(cls, data: dict) -> RefinementTrial:
        return cls(data["step"], data["effect"], data["change"], data["tried"],
                   LikelihoodRatio.from_dict(data["lr"]), dict(data["estimates"]),
                   data["note"], data["kept"])


def refinements_of(spec: ModelSpec, fit: Fit, names: list[str]
                   ) -> list[tuple[str, Refinement]]:
    """Each refinement (`Effect.refinements`) of the effects of `spec` named in `names`."""
    return [(e.name, r) for e in spec.effects if e.name in names
            for r in e.refinements(fit.test)]


def refine(fit: Fit, spec: ModelSpec, names: list[str], step: int, alpha: float,
           progress: bool = False) -> list[RefinementTrial]:
    """Every refinement of the effects `names` of `spec` (fitted as `fit`, chain step
    `step`), each refitted from `fit` and tested by its likelihood ratio at alpha / m
    over the m tried (module docstring); empty where none of them has one."""
    asked = refinements_of(spec, fit, names)
    trials = []
    for name, r in asked:
        refined = dataclasses.replace(spec, effects=tuple(
            r.effect if e.name == name else e for e in spec.effects))
        trial = RefinementTrial(step, name, r.change, len(asked), spec=refined)
        found = _lowest_refit(fit, refined, [r.null, *r.starts], progress)
        if isinstance(found, str):
            trial.note = found
            trials.append(trial)
            continue
        est, new = found
        trial.lr = LikelihoodRatio(fit.chi_square - new.chi_square, len(r.null))
        trial.estimates = {n: new.parameters[n] for n in r.null}
        trial.refitted = (est, new)
        trial.kept = trial.lr.p_value < alpha / len(asked)
        trials.append(trial)
    return trials


def _lowest_refit(fit: Fit, spec: ModelSpec, starts: list[dict[str, float]],
                  progress: bool) -> tuple[Estimator, Fit] | str:
    """`spec` refitted from `fit` with the freed constants at each of `starts` (the first
    the null): the converged refit with the lowest chi-square, or why none converged.

    From a start other than the null the constants are first held there while the
    rest is refitted, then freed from that fit: `fit`'s other parameters are bent to
    the null, and freed at once the constants slide back to the nearest minimum.  On
    `drogue` flown with added mass growing as D^6, the refit from the D^3 law's fit
    with the exponent freed at 6 ended at 3.98 (chi-square 7,548.3); held at 6 the
    refit reached 7,108.2, and freed from there 5.72 (7,103.2).  Every held start is
    freed, not only the lowest: a held fit is a constrained one.  On late canopy
    breathing the lowest held start of the modulation ended above the refit freed from
    the null (which had stopped 0.76 s early, at chi-square/dof 1.056), and yet,
    freed, the refits from them reached the truth's 14.5 s (0.994)."""
    found: list[tuple[Estimator, Fit]] = []
    failures = []

    def attempt(what: str, start: Fit, values: dict[str, float], fixed: bool
                ) -> tuple[Estimator, Fit] | None:
        model = dataclasses.replace(spec, fix={**spec.fix, **values}) if fixed else spec
        try:
            return refit(start, model, values=values, progress=progress,
                         max_iter=REFINE_MAX_ITER)
        except (SolverFailure, InputError) as exc:
            failures.append(f"{what} {_values_text(values)}: {exc}")
            return None

    free = attempt("from", fit, starts[0], fixed=False)
    found += [free] if free is not None else []
    for values in starts[1:]:
        held = attempt("held at", fit, values, fixed=True)
        freed = None if held is None else attempt("freed from", held[1], values, fixed=False)
        found += [freed] if freed is not None else []
    if not found:
        return "no refit converged (" + "; ".join(failures) + ")"
    return min(found, key=lambda f: f[1].chi_square)


def _values_text(values: dict[str, float]) -> str:
    return ", ".join(f"{n} = {v:.4g}" for n, v in values.items())


def best_kept(trials: list[RefinementTrial]) -> RefinementTrial | None:
    """The kept refinement with the smallest p-value (the largest ratio among ties)."""
    kept = [t for t in trials if t.kept and t.lr is not None]
    return min(kept, key=lambda t: (t.lr.p_value, -t.lr.statistic), default=None)
