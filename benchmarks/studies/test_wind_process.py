"""The wind process: air motion estimated with the trajectory under a Gauss-Markov prior.

A `drogue` test flown through gusts drawn from the process (vertical 0.5 m/s,
horizontal 1 m/s, correlation time 5 s, knots every second) misfits its noise in
still air; with the process the fit is within the noise and the drag areas are
back at the truth.  In still air the fitted wind is consistent with zero.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.cli import main
from cpas_ocp.discrepancy.diagnosis import ALPHA as DIAGNOSIS_ALPHA
from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.wind_evidence import DECISIVE_2LNB, wind_evidence
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.inference.process_intensity import choose_intensity
from cpas_ocp.inference.result_claim import PROCESS_SIGMAS
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_block, spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects.registry import BASELINE
from cpas_ocp.physics.effects.wind_process import WindProcess
from cpas_ocp.reports.discrepancy_text import wind_evidence_text
from cpas_ocp.reports.flight_report import air_motion_text

pytestmark = pytest.mark.slow

WIND = {"effects": ["wind_process", *BASELINE]}
ALPHA = 1e-3


def _fit(test, block=None):
    spec = None if block is None else spec_from_block(block, "model.json", Path())
    est, fit, _ = solve_checked(Estimator(test, spec))
    return fit, est.covariance(fit)


def _chi2_p(fit) -> float:
    return float(chi2.sf(fit.chi_square, fit.dof))


@pytest.fixture(scope="module")
def gusty(tmp_path_factory) -> tuple[Path, dict[str, float]]:
    problem = load_problem("drogue")
    problem = dataclasses.replace(problem, simulation={
        **problem.simulation, "model": WIND, "drawn": ["wind_process"]})
    folder = tmp_path_factory.mktemp("gusty") / "test"
    simulate_problem(problem, folder, seed=1)
    return folder, json.loads((folder / "truth.json").read_text())["parameters"]


def test_gusts_misfit_still_air_and_fit_the_noise_with_the_process(gusty) -> None:
    folder, truth = gusty
    test = load_test(folder)
    still, _ = _fit(test)
    assert _chi2_p(still) < ALPHA  # the air moved and the model did not know it
    fit, cov = _fit(test, WIND)
    assert _chi2_p(fit) > ALPHA, fit.chi_square / fit.dof
    std = cov.std
    for name in fit.free:
        if name.startswith("CdS"):
            assert abs(fit.parameters[name] - truth[name]) < 4.0 * std[name], name
    # The vertical air motion itself: closer to the truth than still air is.
    up = [n for n in fit.free if n.startswith("wind_up")]
    error = np.array([fit.parameters[n] - truth[n] for n in up])
    assert np.sqrt(np.mean(error**2)) < 0.5 * np.sqrt(np.mean([truth[n] ** 2 for n in up]))


def test_in_still_air_the_fitted_wind_is_consistent_with_zero(drogue_folder) -> None:
    fit, cov = _fit(load_test(drogue_folder(1)), WIND)
    names = [n for n in fit.free if n.startswith("wind")]
    index = [cov.names.index(n) for n in names]
    C = cov.matrix[np.ix_(index, index)]
    w = np.array([fit.parameters[n] for n in names])
    assert chi2.sf(float(w @ np.linalg.pinv(C) @ w), len(names)) > ALPHA
    assert _chi2_p(fit) > ALPHA


def test_the_marginal_likelihood_finds_the_gusts_intensity(gusty) -> None:
    """The gusts were drawn at 0.5 m/s vertical: of a quarter, the same and four times that,
    the evidence picks the same."""
    folder, _ = gusty
    spec = spec_from_block(WIND, "model.json", Path())
    choice = choose_intensity(load_test(folder), spec, (0.25, 1.0, 4.0))
    assert choice.best.sigma_vertical == pytest.approx(0.5)
    assert all(p.evidence is not None for p in choice.points)


def test_in_still_air_the_evidence_picks_the_weakest_process_and_the_sigmas_stay(
        drogue_folder) -> None:
    """The null check: in still air the smallest intensity wins, and there the drag areas'
    sigmas are within 10 % of the still-air model's."""
    test = load_test(drogue_folder(1))
    choice = choose_intensity(test, spec_from_block(WIND, "model.json", Path()),
                              (0.0625, 1.0))
    assert choice.best.sigma_vertical == pytest.approx(0.0625 * 0.5)
    still, still_cov = _fit(test)
    std = choice.estimator.covariance(choice.fit).std
    for name in still.free:
        if name.startswith("CdS"):
            assert std[name] < 1.1 * still_cov.std[name], name


def test_the_drawn_process_has_its_stated_variance_and_correlation() -> None:
    effect = WindProcess(components=("up",), knot_s=1.0, tau_s=5.0, sigma_vertical=0.5)
    phase = SimpleNamespace(t_start=0.0, t_end=40000.0)
    draw = effect.draw(phase, np.random.default_rng(7))
    u = np.array([draw[f"wind_up[{k}]"] for k in range(len(draw))])
    phi = math.exp(-1.0 / 5.0)
    # 40,001 knots of an AR(1) with phi = 0.82: about 4,000 independent samples, so the
    # variance is within 3 x sqrt(2/4000) = 7 % and the lag-1 correlation within 0.02.
    assert np.var(u) == pytest.approx(0.25, rel=0.07)
    assert np.corrcoef(u[:-1], u[1:])[0, 1] == pytest.approx(phi, abs=0.02)
    assert effect.draw(phase, np.random.default_rng(7)) == draw  # seeded


@pytest.mark.parametrize("block, expected", [
    ({"effects": [*BASELINE[:1], "wind_process", *BASELINE[1:]]}, "before the effects"),
    ({"effects": [{"effect": "wind_process", "tau_s": 0}, *BASELINE]}, "tau_s"),
    ({"effects": [{"effect": "wind_process", "components": ["down"]}, *BASELINE]},
     "components"),
])
def test_a_misplaced_or_misconfigured_wind_process_is_an_input_error(drogue_folder, block,
                                                                     expected) -> None:
    test = load_test(drogue_folder(1))
    with pytest.raises(InputError, match=expected):
        spec_from_block(block, "model.json", Path()).model(test)


def test_an_axial_accelerometer_is_a_fitted_sensor(tmp_path) -> None:
    """`drogue` with a body-fixed axial accelerometer (100 Hz, 0.5 m/s^2) hanging at a mean
    cosine of 0.8 to the specific force: the fit recovers the cosine and fits the
    accelerometer to its noise."""
    problem = load_problem("drogue")
    manifest = {**problem.manifest, "sensors": [*problem.manifest["sensors"], {
        "name": "accelerometer", "kind": "axial_accelerometer", "file": "accelerometer.csv",
        "columns": {"time": "s", "acceleration": "m/s^2"},
        "sigma": {"acceleration": {"value": 0.5, "unit": "m/s^2"}}}]}
    model = {"effects": [*BASELINE, "axial_accelerometer"]}
    truth = {**problem.truth, "axis_cos[drogue1]": 0.8, "axis_cos[drogue2]": 0.8}
    simulation = {**problem.simulation, "model": model,
                  "rates_hz": {**problem.simulation["rates_hz"], "accelerometer": 100}}
    problem = dataclasses.replace(problem, manifest=manifest, simulation=simulation,
                                  truth=truth)
    simulate_problem(problem, tmp_path / "test", seed=1)
    fit, cov = _fit(load_test(tmp_path / "test"), model)
    assert _chi2_p(fit) > ALPHA
    for name in ("axis_cos[drogue1]", "axis_cos[drogue2]"):
        assert abs(fit.parameters[name] - 0.8) < 4.0 * cov.std[name], name
    accel = next(r for r in fit.residuals if r.sensor == "accelerometer")
    assert np.sqrt(np.mean(accel.normalised**2)) < 1.1


def test_a_rocket_descent_through_gusts_is_reconstructed_with_the_process(tmp_path) -> None:
    """`rocket_gusts` (barometer, GPS altitude and axial accelerometer at Altus Metrum rates
    and noise, vertical gusts of 1 m/s): in still air the drag areas come out many sigma
    off at a chi-square far beyond the noise; with the process the gusts came from, the
    fit is within the noise and the drag areas, the main's start and the accelerometer's
    axis cosines are within 4 sigma of the truth."""
    problem = load_problem("rocket_gusts")
    simulate_problem(problem, tmp_path / "test", seed=1)
    truth = json.loads((tmp_path / "test" / "truth.json").read_text())["parameters"]
    test = load_test(tmp_path / "test")
    still, still_cov = _fit(test)
    assert _chi2_p(still) < ALPHA
    assert max(abs(still.parameters[n] - truth[n]) / still_cov.std[n]
               for n in ("CdS[drogue,stage1]", "CdS[main,stage2]")) > 4.0
    manifest_model = problem.manifest["model"]
    wind = {**manifest_model, "effects": [problem.simulation["model"]["effects"][0],
                                          *manifest_model["effects"]]}
    fit, cov = _fit(test, wind)
    assert _chi2_p(fit) > ALPHA, fit.chi_square / fit.dof
    for name in ("CdS[drogue,stage1]", "CdS[main,stage2]", "t_start[main,stage2]",
                 "axis_cos[drogue]", "axis_cos[main]"):
        assert abs(fit.parameters[name] - truth[name]) < 4.0 * cov.std[name], name
    # The flight report's comparison of the two fits.
    text = air_motion_text(still, still_cov, fit, cov, "wind.png")
    assert (f"| χ²/dof | {still.chi_square / still.dof:.2f} | "
            f"{fit.chi_square / fit.dof:.2f} |") in text
    assert "| CdS[main,stage2] |" in text and "wind_process" in text
    assert "| baro.altitude, normalised RMS |" in text and "](wind.png)" in text


def test_the_command_line_chooses_the_intensity_and_refuses_a_model_without_a_process(
        tmp_path, capsys) -> None:
    from cpas_ocp.cli import main
    problem = load_problem("rocket_gusts")
    simulate_problem(problem, tmp_path / "test", seed=1)
    model = problem.manifest["model"]
    wind = {**model, "effects": [problem.simulation["model"]["effects"][0], *model["effects"]]}
    (tmp_path / "wind.json").write_text(json.dumps(wind))
    assert main(["reconstruct", str(tmp_path / "test"), "--model", str(tmp_path / "wind.json"),
                 "--wind-intensity", "0.5,1,2", "--out", str(tmp_path / "report")]) == 0
    out = capsys.readouterr().out
    # The gusts were drawn at 1 m/s: the evidence picks it.
    assert "vertical  1.000 m/s: chi-square" in out and out.count("<- chosen") == 1
    chosen = next(line for line in out.splitlines() if "<- chosen" in line)
    assert "vertical  1.000 m/s" in chosen
    claim = json.loads((tmp_path / "report" / "result.json").read_text())["claim"]
    assert claim["notes"] == ["wind-process intensity chosen by marginal likelihood: "
                              "vertical 1 m/s of 0.5, 1, 2 m/s"]
    assert main(["reconstruct", str(tmp_path / "test"), "--wind-intensity", "1,2",
                 "--out", str(tmp_path / "still")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a wind_process effect" in err[0]
    assert not (tmp_path / "still").exists()


def test_a_held_profile_whose_refits_all_failed_claims_nothing() -> None:
    """A held parameter whose every refit failed has no profile: the report says so and
    lists the failures, and does not say the data leave it undetermined."""
    from cpas_ocp.inference.profile_likelihood import Profile
    from cpas_ocp.reports.flight_report import held_lines
    failed = [(v, "Maximum_Iterations_Exceeded after 100 iterations") for v in (0.5, 2.0)]
    alone = Profile("expopen[main,stage2]", "1", 1.0, float("nan"), np.array([1.0]),
                    np.array([0.0]), failed, [{"n[main,stage2]": 4.0}])
    [line] = held_lines(alone, 1.3, ["n[main,stage2]"])
    assert "could not be made" in line and "do not determine" not in line
    assert "0.5 (Maximum_Iterations_Exceeded" in line and "2 (Maximum" in line
    # With a converged point beside the held one, the profile speaks.
    pair = Profile("expopen[main,stage2]", "1", 1.0, float("nan"), np.array([1.0, 2.0]),
                   np.array([0.0, 0.4]), failed[:1],
                   [{"n[main,stage2]": 4.0}, {"n[main,stage2]": 6.0}])
    lines = held_lines(pair, 1.3, ["n[main,stage2]"])
    assert "these data do not determine it" in lines[0] and "from 4 to 6" in lines[0]
    assert lines[1].strip().startswith("Points that failed: 0.5")


def _rocket(tmp_path: Path, seed: int, gusts: bool):
    """`rocket_gusts` flown through its gusts, or in still air, and fitted in still air."""
    problem = load_problem("rocket_gusts")
    if not gusts:
        truth = problem.simulation["model"]
        problem = dataclasses.replace(problem, simulation={
            **problem.simulation, "drawn": [], "model": {"effects": truth["effects"][1:]}})
    simulate_problem(problem, tmp_path / f"seed{seed}", seed)
    test = load_test(tmp_path / f"seed{seed}")
    spec = spec_of_test(test)
    return Estimator(test, spec).solve(), spec


def test_the_diagnosis_names_the_air_motion_through_gusts_and_not_in_still_air(
        tmp_path) -> None:
    """Through gusts of 1 m/s the altimeter and the GPS share their residual, and the
    evidence of a vertical wind process over still air is decisive (2 ln B >= 10): the
    diagnosis's verdict names it.  In still air the altitude sensors share nothing, so the
    question is not asked; asked anyway, the evidence does not favour the process."""
    fit, spec = _rocket(tmp_path, 3, gusts=True)
    air = wind_evidence(fit, spec, DIAGNOSIS_ALPHA)
    assert air is not None and air.common_p < DIAGNOSIS_ALPHA
    assert air.decisive and air.two_ln_b >= DECISIVE_2LNB
    assert air.best_fit.chi_square < fit.chi_square
    diag = Diagnosis(fit, [], [], [], [], air=air)
    assert diag.verdict().startswith("missing effect: wind_process, the air's vertical motion")
    assert "2 ln B" in wind_evidence_text(air) and "sigma 1 m/s" in wind_evidence_text(air)
    still, still_spec = _rocket(tmp_path, 4, gusts=False)
    assert wind_evidence(still, still_spec, DIAGNOSIS_ALPHA) is None
    forced = wind_evidence(still, still_spec, 1.0)
    assert forced is not None and not forced.decisive


def wind_model(folder: Path, dest: Path, sigma: float) -> Path:
    """The test's model with the air's vertical motion as a process of prior `sigma` (m/s)."""
    model = json.loads((folder / "manifest.json").read_text())["model"]
    model["effects"] = [{"effect": "wind_process", "components": ["up"], "knot_s": 4.0,
                         "tau_s": 10.0, "sigma_vertical": sigma}] + model["effects"]
    dest.write_text(json.dumps(model))
    return dest


@pytest.mark.parametrize(("sigma", "code"), [(0.05, 4), (1.0, 0)])
def test_a_wind_process_beyond_its_prior_exits_4(problem_folder, tmp_path, capsys,
                                                 sigma: float, code: int) -> None:
    """rocket_gusts (seed 2) flown through air of 1 m/s: fitted with a prior of 0.05 m/s the
    knots go beyond 5 sigma of it (exit 4, the knot and its sigma named); with the prior
    it was drawn from, a result."""
    folder = problem_folder("rocket_gusts", 2)
    model = wind_model(folder, tmp_path / "model.json", sigma)
    out = tmp_path / "out"
    assert main(["reconstruct", str(folder), "--model", str(model), "--out", str(out)]) == code
    claim = json.loads((out / "result.json").read_text())["claim"]
    if code:
        err = capsys.readouterr().err
        assert "a process departs from its prior beyond 5 sigma: wind_process: wind_up[" in err
        assert "sigma of its prior" in err
        knots = [d for d in claim["process_departures"] if d["kind"] == "knot"]
        assert knots and all(abs(d["sigmas"]) > PROCESS_SIGMAS for d in knots)
    else:
        assert claim["result"] is True and claim["process_departures"] == []
