"""A joint reconstruction of tests that share hardware: one NLP, shared parameters declared.

Tests flown with the same canopies, forebody or instruments share what that
hardware is: one drag area per canopy type and stage, one pressure recovery
fraction (PRF) per forebody, one scale per load cell.  Fitted one at a time,
each test estimates its own copy, and a quantity that enters one test only
through a product (PRF*CdS, paper Eqs. 2-3) is not determined at all.  Fitted
jointly (`estimation.joint_nlp`), the copies are one parameter and every
test's data speak to it: tests behind a small vehicle (PRF = 1) fix the drag
area, tests behind the capsule then fix its PRF.

Declaring what is shared: `share` maps a parameter's base name (``CdS``,
``prf``, ``loadcell_scale``) to what its copies are shared over:

* ``"type"``: one value per parameter name with every canopy replaced by its
  type (``CdS[fbcp1,stage1]`` and ``CdS[fbcp2,stage1]`` of every test are
  ``CdS[fbcp,stage1]``; a sensor's name stays, so ``loadcell_scale[riser1]`` is
  one instrument's);
* ``"vehicle"``: as ``"type"``, separately for each test vehicle (by its
  manifest name): one PRF per forebody.

A parameter fixed by default (a PRF) is freed in every test where it is shared.
The rest stay per test.  Each test is first fitted alone with its own model (a parameter it holds
fixed by default held there), which is both the joint fit's start and the
input of a two-stage estimate (`campaign.population_model`).  The joint fit
starts there, every copy of a shared parameter at the inverse-variance mean
of the copies the tests determine alone (else their median).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as chi2_law

from cpas_ocp.estimation.estimator import Estimator, Fit, Settings, SolverStats
from cpas_ocp.estimation.joint_nlp import JointNlp, Link
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.result_claim import ALPHA
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.parameters import param_name, split_name

SHARE_OVER = ("type", "vehicle")


class SharingError(ValueError):
    """The declaration of what is shared does not fit the tests."""


def fit_problems(chi2: float, dof: int, undetermined: Sequence[str], covariance: Covariance
                 ) -> list[str]:
    """Why a fit of several tests in one NLP is not a result (empty where it is): a
    chi-square beyond the tests' noise (p below `result_claim.ALPHA`, the single fit's
    level), a joint parameter the tests do not determine together (`undetermined`),
    parameters the `covariance` finds held at a bound."""
    out = []
    p_value = float(chi2_law.sf(chi2, max(dof, 1)))
    if p_value < ALPHA:
        out.append(f"chi-square {chi2:.1f} on {dof} degrees of freedom (p = {p_value:.2g}) is "
                   "beyond the tests' noise: the shared parameters may differ between the "
                   "tests, or the model lacks an effect")
    if undetermined:
        out.append(f"the tests together do not determine {', '.join(undetermined)}")
    if covariance.at_bound:
        out.append(f"held at a bound: {', '.join(covariance.at_bound)}")
    return out


def shared_key(name: str, test: FlightTest, over: str) -> str:
    """The joint name of a test's parameter `name` shared `over` "type" or "vehicle"."""
    if over not in SHARE_OVER:
        raise SharingError(f"a parameter is shared over one of {SHARE_OVER}; got {over!r}")
    base, index = split_name(name)
    types = {c.name: c.type for c in test.parachutes}
    key = param_name(base, *(types.get(a, a) for a in index))
    return key if over == "type" else f"{key}@{test.vehicle.name}"


def shared_links(tests: Sequence[FlightTest], free: Sequence[Sequence[str]],
                 share: Mapping[str, str]) -> list[Link]:
    """The links of the shared parameters among the tests' `free` parameter names: one per
    joint name with copies in at least two places."""
    groups: dict[str, list[tuple[int, str]]] = {}
    for i, (test, names) in enumerate(zip(tests, free, strict=True)):
        for name in names:
            base, _ = split_name(name)
            if base in share:
                groups.setdefault(shared_key(name, test, share[base]), []).append((i, name))
    return [Link(key, tuple(members)) for key, members in groups.items() if len(members) > 1]


@dataclass(frozen=True)
class SharedEstimate:
    """A shared parameter's joint estimate (SI) and standard deviation, with its copies;
    `std` is NaN where the tests together do not determine it either (`undetermined`)."""

    name: str
    value: float
    std: float
    members: tuple[tuple[int, str], ...]

    @property
    def determined(self) -> bool:
        return bool(np.isfinite(self.std))


@dataclass
class JointFit:
    """Several tests reconstructed in one NLP with shared parameters.

    `fits`: each test at the joint solution; `individual` and
    `individual_covariances`: each test fitted alone (the joint fit's start, and a
    two-stage estimate's input); `covariance`: every free parameter of every test,
    named ``"<test index>:<parameter>"``; `shared`: the shared parameters.
    """

    labels: list[str]
    fits: list[Fit]
    individual: list[Fit]
    individual_covariances: list[Covariance]
    shared: list[SharedEstimate]
    covariance: Covariance
    stats: SolverStats
    n_residuals: int
    n_free: int

    @property
    def chi2(self) -> float:
        """The joint chi-square (every test's weighted residuals)."""
        return 2.0 * self.stats.objective

    @property
    def dof(self) -> int:
        """Residuals less the free parameters (each shared one counted once)."""
        return self.n_residuals - self.n_free

    @property
    def fit_p_value(self) -> float:
        """The chance of a chi-square this large from the tests' noise alone."""
        return float(chi2_law.sf(self.chi2, max(self.dof, 1)))

    @property
    def problems(self) -> list[str]:
        """Why the joint fit is not a result (empty where it is): `fit_problems`."""
        return fit_problems(self.chi2, self.dof, [s.name for s in self.shared
                                                  if not s.determined], self.covariance)

    @property
    def is_result(self) -> bool:
        return not self.problems

    def estimate(self, name: str) -> SharedEstimate:
        """The shared parameter `name`'s estimate."""
        for s in self.shared:
            if s.name == name:
                return s
        raise KeyError(f"no shared parameter {name!r}; shared: {[s.name for s in self.shared]}")

    def __repr__(self) -> str:
        return (f"JointFit({len(self.fits)} tests, {len(self.shared)} shared parameters, "
                f"chi2/dof {self.chi2 / max(self.dof, 1):.3f})")


def _estimators(tests: Sequence[FlightTest], share: Mapping[str, str],
                settings: Settings | None) -> list[tuple[Estimator, dict[str, float]]]:
    """Each test's estimator, the shared parameters its model holds fixed by default freed,
    and those parameters' default values (where its own fit holds them)."""
    out = []
    for test in tests:
        est = Estimator(test, settings=settings)
        extra = [p.name for p in est.model.parameters
                 if split_name(p.name)[0] in share and p.name not in est.free]
        held = {name: est.values[name] for name in extra}
        if extra:
            base = settings or Settings()
            est = Estimator(test, settings=replace(base, free=[*est.free, *extra]))
        out.append((est, held))
    return out


def start_value(link: Link, fits: Sequence[Fit], covs: Sequence[Covariance]) -> float:
    """Where a shared parameter's copies start: the inverse-variance mean of the copies the
    tests determined alone, else the median of their values."""
    values, weights = [], []
    for t, name in link.members:
        cov = covs[t]
        std = cov.std.get(name, np.inf)
        values.append(fits[t].parameters[name])
        determined = name not in cov.undetermined and name not in cov.at_bound
        weights.append(1.0 / std**2 if determined and 0.0 < std < np.inf else 0.0)
    w = np.asarray(weights)
    if w.sum() > 0.0:
        return float(w @ np.asarray(values) / w.sum())
    return float(np.median(values))


def fits_alone(tests: Sequence[FlightTest], share: Mapping[str, str],
               settings: Settings | None, labels: Sequence[str], say: Callable[[str], None]
               ) -> tuple[list[Estimator], list[Link], list[Fit], list[Covariance]]:
    """Each test's estimator (the parameters named in `share` free), the links of their
    copies across the tests, and each test fitted alone with its covariance: the start of
    a joint or hierarchical fit.  SharingError where no parameter named in `share` is free
    in two places."""
    built = _estimators(tests, share, settings)
    ests = [est for est, _ in built]
    links = shared_links(tests, [e.free for e in ests], share)
    if not links:
        raise SharingError(f"no parameter named in share ({', '.join(share)}) is free in two "
                         "places of these tests")
    fits, covs = [], []
    for label, (est, held) in zip(labels, built, strict=True):
        say(f"fitting {label} alone")
        # Alone, a test's model is its own: a parameter it holds fixed by default stays
        # at its default value (a PRF, which one test cannot tell from the drag area).
        fit = est.solve(bounds={name: (value, value) for name, value in held.items()})
        fits.append(fit)
        covs.append(est.covariance(fit))
    return ests, links, fits, covs


def joint_fit(tests: Sequence[FlightTest], share: Mapping[str, str],
              settings: Settings | None = None, labels: Sequence[str] | None = None,
              progress: Callable[[str], None] | None = None) -> JointFit:
    """Reconstruct `tests` in one NLP, the parameters named in `share` held equal across
    them (module docstring).  Raises SolverFailure where a test's own fit or the joint
    run fails (its status and iterations), SharingError where nothing is shared."""
    say = progress or (lambda _: None)
    labels = list(labels) if labels is not None else [t.name for t in tests]
    ests, links, fits, covs = fits_alone(tests, share, settings, labels, say)
    say(f"joint fit of {len(tests)} tests, {len(links)} shared parameters")
    nlp = JointNlp(ests, links)
    z, stats = nlp.solve(nlp.start(fits, {k.name: start_value(k, fits, covs) for k in links}))
    cov = nlp.covariance(z)
    shared = []
    for link in links:
        t, name = link.members[0]
        key = f"{t}:{name}"
        i = nlp.names.index(key)
        shared.append(SharedEstimate(link.name, float(z[nlp.param_index[i]] * nlp.pscale[i]),
                                     cov.std.get(key, np.nan), link.members))
    n_free = len(nlp.names) - sum(len(k.members) - 1 for k in links)
    return JointFit(labels, nlp.fits(z, stats), fits, covs, shared, cov, stats,
                    nlp.n_residuals, n_free)
