"""Discovery on data with two hidden effects: one step per effect, until the noise.

FBCP seed 1 is flown with added mass (k_A = 1.4 per canopy) and a 0.1 s GPS
latency, and the baseline model is fitted from the offline reduction.  One
diagnosis confirms one effect; `discover` must add both, one per step, each
admitted by a likelihood ratio significant at the family-wise level, stop
because the residuals are consistent with the noise, and end at the truth
within the noise.  Each step's model must be written as a model file that
loads again.

After the lag is added, fairlead friction of the wrong sign (a stand-in for the
air mass) leads the score tests and added mass comes second: a diagnosis that
refits only its leader must refit past the stand-in and confirm added mass.
"""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.cli import main
from cpas_ocp.discrepancy.diagnosis import ALPHA, diagnose
from cpas_ocp.discrepancy.discovery import DiscoveryStep, discover, next_step
from cpas_ocp.discrepancy.score_test import rank
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec, load_model_file
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import AddedMass, SensorLag, baseline_effects
from cpas_ocp.reports.discrepancy_report import write_discovery
from cpas_ocp.reports.discrepancy_text import diagnosis_text, discovery_text
from tests.conftest import assert_truth_within_noise

pytestmark = pytest.mark.slow

HIDDEN = {**{f"added_mass_factor[{c}]": 1.4 for c in ("fbcp1", "fbcp2")}, "lag[gps]": 0.1}


@pytest.fixture(scope="module")
def two_hidden(tmp_path_factory):
    """(test folder, truth, discovery, its output folder)."""
    problem = load_problem("fbcp")
    folder = tmp_path_factory.mktemp("two-hidden") / "test"
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **HIDDEN}), folder,
                     1, effects=[*baseline_effects(), AddedMass(), SensorLag.gps()])
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    (folder / "truth.json").unlink()  # the estimator's folder carries no truth
    fit = Estimator(load_test(folder), baseline_spec()).solve()
    found = discover(fit, baseline_spec(), max_steps=3)
    out = write_discovery(found, folder.parent / "discovery")
    return folder, truth, found, out


def test_each_hidden_effect_is_added_in_a_step_of_its_own(two_hidden) -> None:
    _, truth, found, _ = two_hidden
    steps = found.steps
    assert [s.added for s in steps[:1]] == [None]
    assert sorted(s.added for s in steps[1:]) == ["added_mass", "gps_lag"], discovery_text(found)
    for before, after in itertools.pairwise(steps):
        # Each fall is the likelihood ratio of a nested pair, significant after correcting
        # for every effect the diagnosis before it tested.
        diag = before.diagnosis
        best = diag.explanation
        assert best is not None and best.effect == after.added
        assert best.refit.p_value < ALPHA / diag.family
        assert after.fit.chi_square == pytest.approx(before.fit.chi_square
                                                     - best.refit.statistic)
    # Together the steps remove the whole excess chi-square of the first fit, to within the
    # spread the noise leaves in the last one (3 sqrt(2 dof)).
    first, last = steps[0], steps[-1]
    excess = first.fit.chi_square - first.fit.dof
    total = sum(s.explained * (b.fit.chi_square - b.fit.dof) for b, s in
                itertools.pairwise(steps)) / excess
    assert abs(total - 1.0) < 3.0 * np.sqrt(2.0 * last.fit.dof) / excess
    assert all(s.explained > 0.0 and s.windows_explained for s in steps[1:])
    assert last.diagnosis.consistent_with_noise
    assert found.stopped == "the residuals are consistent with the noise"
    assert found.state == "consistent" and found.noise.p_value >= ALPHA
    assert last.fit.chi_square < chi2.ppf(0.999, last.fit.dof)
    est = Estimator(last.fit.test, last.spec, last.fit.settings)
    assert_truth_within_noise(last.fit, est.covariance(last.fit), truth)


def test_each_step_is_a_model_file_and_the_report_shows_the_fall(two_hidden) -> None:
    _, _, found, out = two_hidden
    for k, step in enumerate(found.steps):
        reloaded = load_model_file(out / f"step_{k}.json")
        assert reloaded.effect_names == step.spec.effect_names
    result = json.loads((out / "discovery.json").read_text(), parse_constant=_not_json)
    chi = [s["chi_square"] for s in result["steps"]]
    assert chi == sorted(chi, reverse=True) and len(chi) == len(found.steps)
    assert (out / "discovery.png").stat().st_size > 0
    # What remains, drawn: the last model's residuals per sensor, each shown in the report.
    figures = sorted(p.name for p in out.glob("residuals_*.png"))
    assert figures and all(f"]({name})" in (out / "discovery.md").read_text()
                           for name in figures)
    text = (out / "discovery.md").read_text()
    header = next(line for line in text.splitlines() if line.startswith("| channel"))
    assert header.count("|") == len(found.steps) + 2  # a column per step
    assert "ending: consistent with the noise: chi-square" in text
    assert result["ending"]["state"] == "consistent"
    assert result["ending"]["noise_test"]["p_value"] >= ALPHA
    # Each step's time, and the last model's parameters with their sigma.
    assert all(s["seconds_to_diagnose"] > 0 for s in result["steps"])
    final = result["final_parameters"]
    assert final and all(v["std"] is not None and v["std"] > 0 for v in final.values())
    assert "## The last model's parameters" in text and "± 1σ" in text
    assert (out / "discovery.html").stat().st_size > 0


def _not_json(name: str) -> None:
    """A strict JSON parser's answer to NaN or Infinity."""
    raise ValueError(f"{name} is not JSON")


def test_a_stand_in_leading_the_score_tests_does_not_hide_the_effect_behind_it(two_hidden
                                                                             ) -> None:
    """Diagnosed with one confirming refit, the fit with the lag has fairlead friction of
    the wrong sign, confirmed and implausible, as its score tests' leader; the diagnosis
    refits past it, in score order, and confirms added mass with plausible estimates,
    which is the next step."""
    _, truth, found, _ = two_hidden
    step = found.steps[1]
    assert step.added == "gps_lag", discovery_text(found)
    diag = diagnose(step.fit, step.spec, confirm_top=1)
    by_score = [t for t in rank(diag.effects) if t.tested]
    leader = by_score[0]
    assert leader.effect == "loadcell_friction", diagnosis_text(diag)
    assert leader in diag.confirmed() and diag.implausible(leader), diagnosis_text(diag)
    refitted = [t.effect for t in by_score if t.refit is not None]
    assert refitted == [t.effect for t in by_score[:len(refitted)]]  # in score order
    added = next(t for t in diag.effects if t.effect == "added_mass")
    assert added in diag.confirmed() and not diag.implausible(added), diagnosis_text(diag)
    found_next = next_step(diag)
    assert isinstance(found_next, DiscoveryStep) and found_next.added == "added_mass"
    assert found_next.fit.chi_square < chi2.ppf(0.999, found_next.fit.dof)
    est = Estimator(found_next.fit.test, found_next.spec, found_next.fit.settings)
    assert_truth_within_noise(found_next.fit, est.covariance(found_next.fit), truth)


def test_discover_refuses_a_step_limit_below_one(two_hidden, tmp_path, capsys) -> None:
    folder, *_ = two_hidden
    assert main(["discover", str(folder), "--out", str(tmp_path / "d"),
                 "--max-steps", "0"]) == 2
    assert "--max-steps" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_the_command_stops_at_its_step_limit_and_says_what_is_left(two_hidden, tmp_path,
                                                                    capsys) -> None:
    """`cpas-ocp discover --max-steps 1` adds the first effect, diagnoses once more, and
    stops saying that the diagnosis confirms the second."""
    folder, _, found, _ = two_hidden
    first, second = found.steps[1].added, found.steps[2].added
    out = tmp_path / "d"
    assert main(["discover", str(folder), "--out", str(out), "--max-steps", "1"]) == 0
    printed = capsys.readouterr().out
    result = json.loads((out / "discovery.json").read_text())
    assert [s["added"] for s in result["steps"]] == [None, first]
    assert result["stopped"].endswith(f"the last diagnosis confirms {second} too")
    assert result["stopped"] in printed and result["ending"]["state"] == "stopped early"
    assert (out / "step_1.json").is_file() and not (out / "step_2.json").exists()


def test_dropping_stand_ins_never_tries_the_effect_just_added(monkeypatch) -> None:
    """After a step adds an effect, the earlier stand-ins are refitted away one by one, and
    the newest effect is not among them, even once a drop has made its step an earlier one
    (it was just admitted against the model without it)."""
    from types import SimpleNamespace

    from cpas_ocp.discrepancy import discovery

    def step(added: str | None, effects: tuple[str, ...], dropped: str | None = None,
             stand_in: bool = True) -> DiscoveryStep:
        return DiscoveryStep(added, SimpleNamespace(effect_names=effects),
                             SimpleNamespace(chi_square=100.0, dof=90),
                             stand_in=["partial"] if stand_in and added else [],
                             dropped=dropped)

    out = discovery.Discovery([step(None, ()), step("gps_lag", ("gps_lag",)),
                               step("loadcell_friction", ("gps_lag", "loadcell_friction")),
                               step("wind_profile", ("gps_lag", "loadcell_friction",
                                                     "wind_profile"))])
    tried = []

    def without(last, name, alpha, progress):
        tried.append(name)
        return step(None, tuple(n for n in last.spec.effect_names if n != name), name)

    monkeypatch.setattr(discovery, "_without", without)
    discovery._drop_stand_ins(out, ALPHA, False)
    assert tried == ["loadcell_friction", "gps_lag"]
    assert [s.label for s in out.steps[4:]] == ["without loadcell_friction", "without gps_lag"]
