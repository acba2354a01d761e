"""A converged fit is a claim: guessed bounds the data press against are moved or reported,
and a chi-square beyond the noise is said, never shown as a plain result."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import cpas_ocp as co
from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference import result_claim
from cpas_ocp.inference.continuation import solve_checked
from cpas_ocp.inference.hypothesis_tests import cone_statistic
from cpas_ocp.inference.result_claim import check_claim
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_block
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.reports.fit_text import claim_text
from tests.conftest import DISCOVER_HOMES, patch_everywhere

pytestmark = pytest.mark.slow

# Every event of the test moved this late: beyond the 1 s start window about each event.
LATE_S = 1.5


def late_events(folder: Path, dest: Path, offset: float) -> Path:
    """A copy of a test folder with every event `offset` s late (their order kept) and no
    truth.json."""
    shutil.copytree(folder, dest)
    (dest / "truth.json").unlink()
    manifest = json.loads((dest / "manifest.json").read_text())
    for event in manifest["events"]:
        event["time"]["value"] += offset
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return dest


def _not_json(token: str) -> None:
    raise AssertionError(f"{token} is not JSON")


def truth_of(folder: Path) -> dict[str, float]:
    return json.loads((folder / "truth.json").read_text())["parameters"]


def test_the_cone_statistic_keeps_only_what_lies_beyond_the_bound() -> None:
    one = np.eye(1)
    beyond, inside = np.array([3.0]), np.array([-3.0])
    zero, inf = np.zeros(1), np.full(1, np.inf)
    assert cone_statistic(beyond, one, zero, inf) == pytest.approx(9.0)
    assert cone_statistic(inside, one, zero, inf) == pytest.approx(0.0, abs=1e-12)
    assert cone_statistic(inside, one, -inf, inf) == pytest.approx(9.0)
    # Correlated: the second coordinate's estimate inside its bound lowers what the first
    # offers, and the decrease is that of the constrained optimum t = (t1, 0).
    C = np.array([[1.0, 0.8], [0.8, 1.0]])
    theta = np.array([2.0, -1.0])
    W = np.linalg.inv(C)
    t1 = theta[0] + W[0, 1] / W[0, 0] * theta[1]  # minimiser of (t - theta)'W(t - theta), t2=0
    d = np.array([t1, 0.0]) - theta
    expected = theta @ W @ theta - d @ W @ d
    assert cone_statistic(theta, C, np.zeros(2), np.full(2, np.inf)) == pytest.approx(expected)


def test_start_windows_move_with_their_shift_and_stop_at_the_phase(drogue_folder) -> None:
    test = load_test(drogue_folder(1))
    name = "t_start[drogue1,stage2]"
    plain = {p.name: p for p in CanopyInflation().parameters(test)}
    moved = {p.name: p for p in CanopyInflation(start_shifts={name: -1.0}).parameters(test)}
    assert moved[name].default == pytest.approx(plain[name].default - 1.0)
    assert (moved[name].lower, moved[name].upper) == pytest.approx(
        (plain[name].lower - 1.0, plain[name].upper - 1.0))
    assert not plain[name].physical_lower and not plain[name].physical_upper
    # A window pushed past the phase's start is cut there, and that bound is physical.
    first = "t_start[drogue1,stage1]"
    early = {p.name: p for p in
             CanopyInflation(start_shifts={first: -100.0}).parameters(test)}[first]
    assert early.lower == test.t_start and early.physical_lower
    assert early.held_side(early.lower) == "lower" and early.is_physical("lower")


@pytest.mark.parametrize("block, field", [
    ({"effects": [{"effect": "canopy_inflation", "start_shifts": {"t_start[nope,stage1]": 1}},
                  "rigid_riser"]}, "model.effects"),
    ({"effects": [{"effect": "canopy_inflation", "start_shifts": {"CdS[drogue1,stage1]": 1}},
                  "rigid_riser"]}, "model.effects[0]"),
    ({"effects": [{"effect": "canopy_inflation", "start_window": 0}, "rigid_riser"]},
     "model.effects[0]"),
])
def test_bad_window_options_are_input_errors(drogue_folder, block, field) -> None:
    test = load_test(drogue_folder(1))
    with pytest.raises(InputError) as info:
        spec_from_block(block, "model.json", Path()).model(test)
    assert info.value.field == field


def test_a_fit_of_the_right_model_is_a_result(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    est = Estimator(fit.test)
    claim = check_claim(est, fit)
    assert claim.is_result and claim.fits_noise and not claim.pressed
    assert claim.problems() == []
    assert claim.fit_p_value > result_claim.ALPHA


def test_events_later_than_the_window_are_recovered_by_moving_the_windows(
        drogue_folder, pressed, monkeypatch) -> None:
    """`solve_checked` on the late events.  Its first fit is the one `pressed` made with
    the same estimator (made once in this module), pressed on the windows' edges;
    everything after it is fitted here."""
    from cpas_ocp.inference import continuation

    truth = truth_of(drogue_folder(1))
    _, rec = pressed
    first_fit = continuation._solve_from_reduction
    monkeypatch.setattr(continuation, "_solve_from_reduction", lambda e, progress: (
        rec.fit if e is rec.estimator else first_fit(e, progress)))
    est, fit, claim = solve_checked(rec.estimator)
    assert est is not rec.estimator
    assert claim.moves and all(m.shift_s < 0 for m in claim.moves)
    assert claim.is_result and claim.fits_noise, claim_text(claim)
    # The truth basin: every start time within 4 sigma of the truth (4 sigma: 24 start
    # times and shape parameters at once; a chance miss has p < 1e-3).
    std = est.covariance(fit).std
    for name in fit.free:
        if name.startswith("t_start"):
            assert abs(fit.parameters[name] - truth[name]) < 4.0 * std[name], name
    assert "window moved" in fit.solver.start


def test_a_first_move_that_does_not_lower_chi_square_leaves_the_fit_to_its_restarts(
        drogue_fit, monkeypatch) -> None:
    """The window move tried before any restart is kept only where it lowers chi-square;
    otherwise the first fit is restarted, and its windows moved from the restarted fit
    where that differs (the fits are stand-ins: what is tested is the order of the
    steps)."""
    from cpas_ocp.inference import continuation

    fit, _, _ = drogue_fit(1)
    est = Estimator(fit.test)
    steps: list[str] = []

    def step(name, value):
        steps.append(name)
        return value

    monkeypatch.setattr(continuation, "_solve_from_reduction",
                        lambda e, p: step("first fit", fit))
    monkeypatch.setattr(continuation, "moved_windows", lambda c, e, f: step(
        "windows at edges?", e.spec))
    monkeypatch.setattr(continuation, "Estimator", lambda test, spec, settings: est)
    monkeypatch.setattr(continuation, "solve", lambda e, p: step("moved refit", fit))
    monkeypatch.setattr(continuation, "_restarted",
                        lambda e, first, p: step("restarts", first()))
    _, kept, claim = continuation.solve_checked(est)
    # The restarts leave the fit as it was: the same move is not tried again.
    assert steps == ["first fit", "windows at edges?", "windows at edges?", "moved refit",
                     "restarts"]
    assert kept is fit and claim.moves == []


def _failed_first_steps(fit, monkeypatch: pytest.MonkeyPatch, moved_is_result: bool
                        ) -> list[str]:
    """`solve_checked`'s steps where the first fit fails with `fit` as its last iterate and
    start times on their windows' edges, each move ending in a claim that is a result at
    the noise or not (stand-ins throughout: what is tested is the order of the steps)."""
    from types import SimpleNamespace

    from cpas_ocp.errors import SolverFailure
    from cpas_ocp.inference import continuation

    steps: list[str] = []
    failure = SolverFailure("Stalled_Without_Progress", 95, "", 363605.0, fit)
    claim = SimpleNamespace(is_result=moved_is_result, fits_noise=moved_is_result, moves=[])

    def first(e, p):
        steps.append("first fit fails")
        raise failure

    def moved(e, f, c, fail, p):
        assert fail is failure and f is fit  # every move here starts at the last iterate
        steps.append("move from the last iterate")
        return e, f, claim, ["a move"], None if moved_is_result else fail

    def restarted(e, given, p):
        steps.append("restarts")
        return given()

    monkeypatch.setattr(continuation, "_solve_from_reduction", first)
    def judged(e, exc):
        steps.append("last iterate judged")
        return claim

    monkeypatch.setattr(continuation, "_judged", judged)
    monkeypatch.setattr(continuation, "moved_windows", lambda c, e, f: "moved spec")
    monkeypatch.setattr(continuation, "_moved", moved)
    monkeypatch.setattr(continuation, "_restarted", restarted)
    monkeypatch.setattr(continuation, "_with_moves", lambda e, f, c, m, fail: (e, f, c))
    return steps


def test_a_failed_first_fit_on_its_edges_is_moved_before_any_restart(
        drogue_fit, monkeypatch) -> None:
    from cpas_ocp.inference import continuation

    fit, _, _ = drogue_fit(1)
    steps = _failed_first_steps(fit, monkeypatch, moved_is_result=True)
    _, kept, claim = continuation.solve_checked(Estimator(fit.test))
    assert steps == ["first fit fails", "last iterate judged", "move from the last iterate"]
    assert claim.is_result and kept is fit


def test_a_failed_first_fit_whose_move_is_no_result_is_restarted_first(
        drogue_fit, monkeypatch) -> None:
    from cpas_ocp.inference import continuation

    fit, _, _ = drogue_fit(1)
    steps = _failed_first_steps(fit, monkeypatch, moved_is_result=False)
    continuation.solve_checked(Estimator(fit.test))
    # The move tried from the stalled iterate is not kept: the restarts go first, as they
    # did before, and the windows are moved from where they end (here the same failure,
    # whose last iterate is judged once).
    assert steps == ["first fit fails", "last iterate judged", "move from the last iterate",
                     "restarts", "move from the last iterate"]


@pytest.fixture(scope="module")
def pressed(drogue_folder, tmp_path_factory):
    """The late events fitted without window moves, which leaves the start times on their
    windows: the folder and its `Reconstruction`, fitted once.  The commands tested with it
    are given this fit where theirs would be made (`given`): the same estimator on the same
    folder, so what they are tested for, what they say of it, is unchanged.  Its fit is
    also the first fit of the window moves tested above.  The restarts stay in: the fit
    from the reduction alone converges pressed or stalls on the same edges depending on
    the last digits of the simulated data (it stalls at chi-square 363,605 after 95
    iterations with numpy 2.4 and scipy 1.17), and the restarts end pressed at 363,204
    either way."""
    folder = late_events(drogue_folder(1), tmp_path_factory.mktemp("pressed") / "late",
                         LATE_S)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("cpas_ocp.inference.continuation.MAX_WINDOW_MOVES", 0)
        return folder, co.reconstruct(folder)


def given(monkeypatch: pytest.MonkeyPatch, rec: co.Reconstruction) -> None:
    """Every fit the interface's workflows make (`api.fit_estimator`) is `rec`."""
    patch_everywhere(monkeypatch, "fit_estimator", lambda *_a, **_k: rec,
                     ("cpas_ocp.api.reconstruction", "cpas_ocp.api.discrepancy"))


def test_a_fit_still_pressed_exits_4_with_its_report_saying_why(
        pressed, tmp_path, monkeypatch, capsys) -> None:
    test_dir, rec = pressed
    given(monkeypatch, rec)
    out = tmp_path / "report"
    code = main(["reconstruct", str(test_dir), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 4, err
    assert "error: the fit converged but is not a result" in err and "t_start[" in err
    result = json.loads((out / "result.json").read_text(), parse_constant=_not_json)
    assert result["claim"]["result"] is False
    assert any(h["pressed"] and h["name"].startswith("t_start")
               for h in result["claim"]["held_bounds"])
    assert result["claim"]["bound_p_value"] < result_claim.ALPHA
    assert (out / "report.md").read_text().count("**Not a result.**") == 1
    assert math.isfinite(result["claim"]["chi_square"])


def test_discover_says_in_its_report_that_its_first_fit_is_not_a_result(
        pressed, tmp_path, monkeypatch) -> None:
    """A chain started from a fit the data press against guessed bounds carries that in
    discovery.json and discovery.md (the diagnoses themselves are replaced by a chain
    that stops at once: what is tested is the command's report of its first fit)."""
    import cpas_ocp.discrepancy.discovery as discovery

    test_dir, rec = pressed
    given(monkeypatch, rec)

    def stopped(fit, spec, *a, **k):
        return discovery.Discovery([discovery.DiscoveryStep(None, spec, fit)],
                                   "stopped before any diagnosis")

    patch_everywhere(monkeypatch, "discover", stopped, DISCOVER_HOMES)
    out = tmp_path / "discovery"
    assert main(["discover", str(test_dir), "--out", str(out)]) == 0
    notes = json.loads((out / "discovery.json").read_text())["notes"]
    assert len(notes) == 1 and notes[0].startswith("the first fit is not a result: the data "
                                                   "press") and "t_start[" in notes[0]
    assert f"note: {notes[0]}" in (out / "discovery.md").read_text()
