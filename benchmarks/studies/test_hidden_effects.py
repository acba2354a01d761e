"""The discrepancy loop on data with a hidden effect: fit without it, diagnose, refit with it.

Each case simulates the FBCP phase with one effect the baseline model lacks,
fits the baseline model (from the offline reduction), and diagnoses the fit:
the score tests of every library effect, confirmed by refits of the
significant ones.  The hidden effect must come out first, with a significant
likelihood ratio, and the refit with it must bring every parameter back to the
truth within the noise.  A wake deficit is invisible in one test (PRF*CdS is
all the data see) unless the free-stream drag areas are known: that case fits
with priors on them, measured with 3 % error (a wind-tunnel or earlier-flight
value), drawn with a seed from the truth.

The null test fits data made with exactly the baseline model: no effect may be
confirmed, and the share of score tests with p < 0.05 must be what chance gives.
"""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import binom

from cpas_ocp.discrepancy.diagnosis import ALPHA, diagnose
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec, baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import (
    AddedMass,
    LoadCellFriction,
    SensorLag,
    WakeDeficit,
    baseline_effects,
    with_elastic_risers,
)
from cpas_ocp.reports.discrepancy_text import diagnosis_text
from tests.conftest import assert_truth_within_noise

pytestmark = pytest.mark.slow

PRIOR_RELATIVE_SIGMA = 0.03
PRIOR_SEED = 7


def _cases() -> dict[str, tuple[list, dict[str, float]]]:
    base = baseline_effects()
    both = ("fbcp1", "fbcp2")
    return {
        "added_mass": ([*base, AddedMass()], {f"added_mass_factor[{c}]": 1.4 for c in both}),
        "elastic_riser": (with_elastic_risers(base),
                          {**{f"riser_period[{c}]": 1.0 / 6.0 for c in both},
                           **{f"riser_damping_ratio[{c}]": 0.3 for c in both}}),
        "loadcell_friction": ([*base, LoadCellFriction()],
                              {f"friction_loss[{c}]": 0.15 for c in both}),
        "gps_lag": ([*base, SensorLag.gps()], {"lag[gps]": 0.1}),
        "wake_deficit": ([base[0], WakeDeficit(prf={"fbcp": 0.85}), *base[1:]], {}),
    }


def _priors(truth: dict[str, float]) -> dict[str, dict[str, float]]:
    """Free-stream drag areas as an independent measurement: truth times (1 + 3 % noise)."""
    rng = np.random.default_rng(PRIOR_SEED)
    out = {}
    for chute in ("fbcp1", "fbcp2"):
        name = f"CdS[{chute},stage1]"
        value = truth[name] * (1.0 + PRIOR_RELATIVE_SIGMA * rng.standard_normal())
        out[name] = {"value": value, "sigma": PRIOR_RELATIVE_SIGMA * value}
    return out


@pytest.fixture(scope="module")
def hidden(tmp_path_factory):
    """A factory: (diagnosis, truth) of the baseline fit to data with the named effect."""
    cache = {}

    def make(case: str):
        if case not in cache:
            effects, values = _cases()[case]
            problem = load_problem("fbcp")
            folder = tmp_path_factory.mktemp(case) / "test"
            simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **values}),
                             folder, 1, effects=effects)
            truth = json.loads((folder / "truth.json").read_text())["parameters"]
            (folder / "truth.json").unlink()  # the estimator's folder carries no truth
            spec: ModelSpec = baseline_spec()
            if case == "wake_deficit":
                spec = dataclasses.replace(spec, priors=_priors(truth))
            fit = Estimator(load_test(folder), spec).solve()
            cache[case] = (diagnose(fit, spec), truth)
        return cache[case]

    return make


@pytest.mark.parametrize("case", list(_cases()))
def test_hidden_effect_is_found_and_its_refit_recovers_the_truth(hidden, case: str) -> None:
    diag, truth = hidden(case)
    ranked = [t.effect for t in diag.effects]
    assert ranked[0] == case, diagnosis_text(diag)
    best = diag.explanation
    assert best is not None and best.effect == case, diag.verdict()
    # Significant after the correction for every effect tested, and far beyond it.
    assert best.refit is not None
    assert best.refit.p_value < ALPHA / diag.tests_made
    est, fit = best.refitted
    assert fit.chi_square < diag.fit.chi_square - best.refit.dof
    cov = est.covariance(fit)
    assert_truth_within_noise(fit, cov, truth)
    for name in best.parameters:
        assert abs(fit.parameters[name] - truth[name]) < 4.0 * cov.std[name], name


def test_wake_deficit_without_priors_is_not_testable(hidden) -> None:
    """Without the priors the PRF cannot be told from the drag areas: the score test says
    so instead of giving a number."""
    diag, _ = hidden("wake_deficit")
    fit = diag.fit
    plain = Estimator(fit.test, baseline_spec()).solve()
    from cpas_ocp.discrepancy.score_test import candidate_effects, score_test
    result = score_test(plain, baseline_spec(), candidate_effects()["wake_deficit"])
    assert not result.tested
    assert set(result.undetermined) == {"prf[fbcp1]", "prf[fbcp2]"}


@pytest.fixture(scope="module")
def null_diagnoses(problem_fit):
    """Diagnoses of baseline fits to data made with the baseline model, seeds 1-4."""
    out = []
    for seed in (1, 2, 3, 4):
        fit, _, _ = problem_fit("fbcp", seed)
        out.append(diagnose(fit, baseline_spec()))
    return out


def test_no_effect_is_flagged_on_data_from_the_fitted_model(null_diagnoses) -> None:
    p_values = [t.p_value for d in null_diagnoses for t in d.effects if t.tested]
    assert len(p_values) >= 20
    for d in null_diagnoses:
        assert d.explanation is None, diagnosis_text(d)
    # Under the null each p-value is uniform (chi-bar-squared where one-sided): the number
    # below 0.05 is binomial(n, 0.05); it must lie inside the central 99.8 % of that law.
    flagged = sum(p < 0.05 for p in p_values)
    low, high = binom.ppf([0.001, 0.999], len(p_values), 0.05)
    assert low <= flagged <= high, (flagged, len(p_values))
    assert all(d.structure == [] for d in null_diagnoses), [d.structure for d in null_diagnoses]



def test_an_effects_states_integrated_through_the_fit_close_their_gaps(hidden) -> None:
    """The null point of elastic risers starts from the rigid fit with the stretch states
    integrated through the fitted motion: their shooting gaps close, and the start is
    nearer feasible than the stretch guessed from the measured tension."""
    diag, _ = hidden("elastic_riser")
    fit = diag.fit
    est = Estimator(fit.test, with_elastic_risers(baseline_effects()))
    null = {n: v for e in est.model.effects if e.name == "elastic_riser"
            for n, v in e.null_values(fit.test).items()}
    z = est.point_from(fit, null)
    names = [st.name for st in est.model.states if st.name.startswith("stretch")]
    swept = est.swept(z, names)
    nx, n = est.model.nx, len(est.t) - 1
    rows = np.concatenate([np.arange(nx)[est.model.state_slice(s)] for s in names])
    gaps = est.transcription.points.constraint_value(swept)[:nx * n].reshape(n, nx)[:, rows]
    assert np.max(np.abs(gaps)) < 1e-9
    assert est.evaluate(swept)[1] < 0.1 * est.evaluate(z)[1]


def test_a_significant_effect_whose_refit_failed_leaves_the_verdict_undecided() -> None:
    """A score test that is significant but whose confirming refit did not converge (elastic
    risers on `drogue` with elastic risers hidden) must not read as noise."""
    from cpas_ocp.discrepancy.diagnosis import Diagnosis
    from cpas_ocp.discrepancy.score_test import ScoreTest
    from cpas_ocp.inference.noise_test import NoiseTest

    failed = ScoreTest("elastic_riser", "library", ("riser_period[d]",), statistic=145.0,
                       dof=4, p_value=2e-31,
                       refit_note="the refit did not converge: solver failed: status "
                                  "Maximum_Iterations_Exceeded after 150 iterations")
    quiet = ScoreTest("gps_lag", "library", ("lag[gps]",), statistic=0.4, dof=1, p_value=0.5)
    verdict = Diagnosis(None, [], [], [failed, quiet], []).verdict()  # type: ignore[arg-type]
    assert verdict.startswith("undecided") and "elastic_riser" in verdict, verdict
    assert "consistent with the sensor noise" not in verdict
    failed.refit_note = ""  # not significant enough to be refitted: no claim either way
    failed.p_value = 0.5
    at_noise = NoiseTest(5700.0, 5723, 0.6, 0.01, 40)  # the chi-square test passed
    assert "consistent with the sensor noise" in Diagnosis(
        None, [], [], [failed, quiet], [], _noise=at_noise).verdict()  # type: ignore[arg-type]


def test_an_unconverged_refit_bounds_the_likelihood_ratio_from_below(hidden, monkeypatch
                                                                    ) -> None:
    """A confirming refit stopped after one iteration still confirms the effect: its last
    iterate, integrated into a feasible point of the extended model, has a chi-square at
    or above the extended optimum, so fit minus point bounds the likelihood ratio of the
    converged refit from below, and its p-value bounds the test's from above."""
    from cpas_ocp.discrepancy import score_test

    diag, _ = hidden("added_mass")
    converged = diag.explanation
    assert converged is not None and not converged.refit.lower_bound
    monkeypatch.setattr(score_test, "CONFIRM_MAX_ITER", 1)
    capped = dataclasses.replace(converged, refit=None, refit_note="", refitted=None)
    score_test.confirm(diag.fit, capped)
    assert "did not converge" in capped.refit_note, capped.refit_note
    bound = capped.refit
    assert bound is not None and bound.lower_bound, capped.refit_note
    # The converged refit stops within the statistical stop's 0.01 of its optimum.
    assert 0.0 < bound.statistic <= converged.refit.statistic + 0.01
    assert bound.p_value < ALPHA / diag.tests_made
    assert ">=" in str(bound) and "<=" in str(bound)
    assert "did not converge" in capped.refit_text()


def test_the_verdict_names_a_bounded_effect_and_warns_of_unconverged_rivals() -> None:
    """An effect confirmed only by a lower bound is named with the bound ('>='); an
    effect confirmed exactly is named with a warning when a significant rival's refit
    did not converge, since that rival may explain more."""
    from cpas_ocp.discrepancy.diagnosis import Diagnosis
    from cpas_ocp.discrepancy.score_test import ScoreTest
    from cpas_ocp.inference.model_comparison import LikelihoodRatio

    bounded = ScoreTest("elastic_riser", "library", ("riser_period[d]",), statistic=145.0,
                        dof=1, p_value=1e-30, refit=LikelihoodRatio(476.0, 1, lower_bound=True),
                        refit_estimate={"riser_period[d]": 0.14},
                        refit_note="the refit did not converge: ...")
    # A fit's chi-square and degrees of freedom: 2,000 beyond what the noise would give.
    fit = SimpleNamespace(chi_square=4000.0, dof=2000)
    verdict = Diagnosis(fit, [], [], [bounded], []).verdict()  # type: ignore[arg-type]
    assert verdict.startswith("missing effect: elastic_riser (likelihood ratio >= 476"), verdict
    exact = ScoreTest("added_mass", "library", ("added_mass_factor[d]",), statistic=900.0,
                      dof=1, p_value=1e-40, refit=LikelihoodRatio(1411.0, 1),
                      refit_estimate={"added_mass_factor[d]": 1.3}, refit_note="37 iterations")
    verdict = Diagnosis(fit, [], [], [exact, bounded], []).verdict()  # type: ignore[arg-type]
    assert verdict.startswith("missing effect: added_mass (likelihood ratio 1411"), verdict
    assert "71 % of the excess chi-square" in verdict  # 1,411 of the excess 2,000
    assert ("the refit of elastic_riser did not converge (likelihood ratio >= 476.0), so it "
            "may explain more") in verdict


def test_a_refit_retried_from_the_effects_defaults_reaches_the_same_optimum(hidden) -> None:
    """The second try of a confirming refit starts at the effect's defaults (8 Hz, zeta 0.3
    for an elastic riser) and ends where the refit from the score step ended; it is not
    made where the defaults are the start already tried."""
    from cpas_ocp.discrepancy.score_test import RETRY_MAX_ITER, _retry_from_defaults

    diag, _ = hidden("elastic_riser")
    result = diag.explanation
    assert result is not None and result.effect == "elastic_riser" and result.refitted
    est, first = result.refitted
    model = result.spec.model(diag.fit.test)
    elsewhere = {n: result.refit_estimate[n] for n in result.parameters}
    retried, note, failure = _retry_from_defaults(est, diag.fit, model, result, elsewhere,
                                                  False)
    assert retried is not None and failure is None, note
    assert retried.solver.iterations <= RETRY_MAX_ITER
    assert abs(retried.chi_square - first.chi_square) < 0.1
    defaults = {n: model.parameter(n).default for n in result.parameters}
    assert _retry_from_defaults(est, diag.fit, model, result, defaults, False) == (None, "",
                                                                                    None)


def test_a_stiff_effect_whose_score_step_leaves_its_bounds_is_refitted_from_its_defaults(
        hidden, monkeypatch) -> None:
    """An elastic riser (brought in by continuation) whose linearised estimates all lie
    outside their bounds offers no step: the refit from the null it would start at is not
    made, the one from the riser's defaults is, and on data flown with 6 Hz risers it
    reaches the optimum the refit from the score step reached."""
    from cpas_ocp.discrepancy.score_test import RETRY_MAX_ITER, confirm

    diag, _ = hidden("elastic_riser")
    result = diag.explanation
    assert result is not None and result.effect == "elastic_riser" and result.refitted
    model = result.spec.model(diag.fit.test)
    outside = {n: model.parameter(n).lower - 1.0 for n in result.parameters}
    stepless = dataclasses.replace(result, estimate=outside, refit=None, refit_estimate={},
                                   refit_note="", refitted=None)
    solves = []
    solve = Estimator.solve

    def counted(self, *args, **kwargs):
        solves.append(kwargs.get("max_iter"))
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(Estimator, "solve", counted)
    confirm(diag.fit, stepless)
    assert solves == [RETRY_MAX_ITER]
    assert "from the effect's defaults (the score step offered no start" in stepless.refit_note
    assert stepless.refit is not None and not stepless.refit.lower_bound
    assert abs(stepless.refit.statistic - result.refit.statistic) < 0.1


def test_a_refit_that_ends_above_the_fit_is_tried_again_from_the_defaults(
        hidden, monkeypatch) -> None:
    """A refit that converges above the fit it extends has found a stationary point, not the
    extended model's optimum: the second try from the effect's defaults is made and the
    lower kept.  The first refit's outcome is made to lie above the fit by doubling its
    residuals (its chi-square four times the refit's, well above the fit's)."""
    from cpas_ocp.discrepancy.score_test import confirm

    diag, _ = hidden("elastic_riser")
    found = diag.explanation
    assert found is not None and found.refit is not None
    result = dataclasses.replace(found, refit=None, refit_estimate={}, refitted=None,
                                 refit_note="")
    solve = Estimator.solve
    calls: list[bool] = []

    def above_first(self, progress=False, start=None, bounds=None, max_iter=None):
        fit = solve(self, progress, start, bounds, max_iter)
        calls.append(True)
        if len(calls) == 1:
            doubled = [dataclasses.replace(r, measured=r.model + 2.0 * (r.measured - r.model))
                       for r in fit.residuals]
            fit = dataclasses.replace(fit, residuals=doubled)
        return fit

    monkeypatch.setattr(Estimator, "solve", above_first)
    confirm(diag.fit, result)
    assert len(calls) == 2
    assert "ended above the fit" in result.refit_note, result.refit_note
    assert result.refit is not None
    assert abs(result.refit.statistic - found.refit.statistic) < 0.1


@pytest.mark.parametrize("lag_s, named", [(0.1, True), (-0.06, False)])
def test_an_implausible_estimate_makes_the_effect_a_stand_in(problem_fit, lag_s: float,
                                                             named: bool) -> None:
    """A GPS lag confirmed at +0.1 s is named as the missing effect; at -0.06 s (the
    receiver reporting before the event) the same likelihood ratio only "partly
    explains" the residual, and the verdict says why."""
    from cpas_ocp.discrepancy.diagnosis import Diagnosis
    from cpas_ocp.discrepancy.score_test import ScoreTest
    from cpas_ocp.inference.model_comparison import LikelihoodRatio

    fit, _, _ = problem_fit("fbcp", 1)
    spec = dataclasses.replace(baseline_spec(),
                               effects=(*baseline_spec().effects, SensorLag.gps()))
    confirmed = ScoreTest("gps_lag", "library", ("lag[gps]",), statistic=60.0, dof=1,
                          p_value=1e-14, refit=LikelihoodRatio(75.0, 1),
                          refit_estimate={"lag[gps]": lag_s}, refit_note="12 iterations",
                          spec=spec)
    verdict = Diagnosis(fit, [], [], [confirmed], []).verdict()
    assert verdict.startswith("missing effect: gps_lag" if named
                              else "partly explained by gps_lag"), verdict
    assert ("lag[gps] = -0.06 lies outside its plausible range 0 to 0.5" in verdict) is not named


def test_an_effect_the_library_lacks_is_not_named_for_one_that_partly_fits(
        tmp_path_factory) -> None:
    """FBCP flown with a load-cell reading loss that grows with the tension (a plug-in the
    library lacks): the library effects that fit part of it are confirmed by their
    likelihood ratios, but the verdict calls the best one a stand-in, says how little of
    the excess it removes, and what remains."""
    from pathlib import Path

    from cpas_ocp.physics.effects.registry import load_plugin

    plugin = Path(__file__).parents[2] / "tests" / "plugins" / "tension_loss.py"
    loss = load_plugin(plugin)["tension_loss"].build({}, str(plugin), "test")
    problem = load_problem("fbcp")
    truth = {**problem.truth, **{f"tension_loss[{c}]": 8e-6 for c in ("fbcp1", "fbcp2")}}
    folder = tmp_path_factory.mktemp("tension-loss") / "test"
    simulate_problem(dataclasses.replace(problem, truth=truth), folder, 1,
                     effects=[*baseline_effects(), loss])
    fit = Estimator(load_test(folder), baseline_spec()).solve()
    diag = diagnose(fit, baseline_spec())
    best = diag.explanation
    assert best is not None  # something in the library fits part of it significantly
    verdict = diag.verdict()
    assert verdict.startswith(f"partly explained by {best.effect}"), verdict
    share = best.refit.statistic / (fit.chi_square - fit.dof)
    assert share < 0.5 and f"{100 * share:.0f} % of the excess chi-square" in verdict
    assert "what remains: " in verdict
