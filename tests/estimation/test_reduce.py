"""`cpas-ocp reduce`: the offline reduction's outputs and the guess it hands the estimator."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.reduction import reduce_and_guess
from cpas_ocp.estimation.stage_curve_fit import (
    StageData,
    curve_and_jacobian,
    fit_stage_curve,
    fitted_names,
)
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.flight_test import Parachute
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.units import FT
from tests.conftest import START_GUESS_OFFSET_S, offset_events

# The stage scale is a ratio of two time means over about 5 s of 100 Hz data;
# noise moves it by well under 0.1 %.  What remains is the model error of
# Eqs. 2-3 (canopy dynamics and dry-mass weight in the steady window), a few
# tenths of a percent on this problem, so 1 % separates a working reduction
# from a broken one.
SCALE_TOLERANCE = 0.01


def test_reduce_writes_curves_guess_and_plot(drogue_folder, tmp_path, capsys):
    folder = drogue_folder(1)
    out = tmp_path / "reduction"
    assert main(["reduce", str(folder), "--out", str(out)]) == 0
    assert "drag_scale[stage2]" in capsys.readouterr().out

    curves = pd.read_csv(out / "reduction.csv")
    assert {"time_s", "cds_imu_m2", "cds_riser_drogue1_m2", "cds_riser_drogue2_m2"} \
        <= set(curves.columns)
    assert curves["time_s"].is_monotonic_increasing
    assert (out / "reduction.png").stat().st_size > 10_000

    guess = json.loads((out / "initial_guess.json").read_text())
    model = Model(load_test(folder), baseline_effects())
    assert set(guess["parameters"]) == {p.name for p in model.parameters if p.estimable}
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    for stage in ("stage1", "stage2", "stage3"):
        name = f"drag_scale[{stage}]"
        assert abs(guess["parameters"][name]["value"] / truth[name] - 1) < SCALE_TOLERANCE, name
    # The two Drogues, mortared 0.1 s apart, open every stage as one cluster.
    groups = guess["stage_groups"]
    assert [(g["stage"], g["canopies"]) for g in groups] == [
        (s, ["drogue1", "drogue2"]) for s in ("stage1", "stage2", "stage3")]
    assert all(g["window_s"][0] < g["window_s"][1] for g in groups)
    assert [g["scale"] for g in groups] == [guess["parameters"][f"drag_scale[{g['stage']}]"]
                                            ["value"] for g in groups]


def test_reduce_refuses_a_foreign_folder(drogue_folder, tmp_path, capsys):
    out = tmp_path / "not-a-reduction"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert main(["reduce", str(drogue_folder(1)), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "initial_guess.json" in err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_curve_fit_recovers_a_noise_free_stage() -> None:
    """The offline fit returns the Eq. 5/6 shape that made a noise-free drag-area history."""
    chute = Parachute("drogue1", "drogue", 23 * FT, 36.0, "infinite_mass", "diameter",
                      ("stage1", "stage2"))
    true = dict(zip(fitted_names(chute, "stage2"), (7.0, 1.22, 5.0, 1.5, 0.25), strict=True))
    bounds = {n: (lo, hi) for n, lo, hi in zip(true, (6.0, 1.0, 0.3, 0.3, 0.01),
                                                   (8.0, 3.0, 40.0, 6.0, 3.0), strict=True)}
    t = np.arange(6.2, 10.0, 0.01)
    airspeed = 90.0 - 2.0 * (t - 6.2)
    blank = StageData(chute, "stage2", t, np.zeros_like(t), airspeed, 7.45, 12.6, 21.0, bounds)
    v_i = float(np.interp(true["t_start[drogue1,stage2]"], t, airspeed))
    cds, _ = curve_and_jacobian(blank)(t[None, :], np.array(list(true.values())), v_i)
    history = np.asarray(cds).ravel()
    fitted = fit_stage_curve(StageData(chute, "stage2", t, history, airspeed, 7.45, 12.6, 21.0,
                                       bounds))
    assert fitted is not None
    for name, value in true.items():
        assert fitted[name] == pytest.approx(value, rel=1e-4, abs=1e-4), name


def test_curve_fit_jacobian_is_the_residual_s_derivative() -> None:
    """The curve fit's Jacobian, exact from CasADi, matches central differences of its
    residual, the start time's column included: through the fill time, the airspeed
    interpolated at the start carries it (a speed falling 30 m/s per second here)."""
    from cpas_ocp.estimation.stage_curve_fit import _WeightedResidual

    chute = Parachute("drogue1", "drogue", 23 * FT, 36.0, "infinite_mass", "diameter",
                      ("stage1", "stage2"))
    t = np.arange(6.2, 10.0, 0.01)
    airspeed = 150.0 - 30.0 * (t - 6.2)
    data = StageData(chute, "stage2", t, np.full_like(t, 9.0), airspeed, 7.45, 12.6, 21.0,
                     {})
    weight = np.linspace(0.5, 1.0, t.size)
    free = np.ones(5, dtype=bool)
    residual = _WeightedResidual(curve_and_jacobian(data), data, weight, lambda x: x, free)
    theta = np.array([7.0037, 1.22, 5.0, 1.5, 0.25])
    jacobian = residual.jacobian(theta).copy()
    for j in range(theta.size):
        h = np.zeros_like(theta)
        h[j] = 1e-6
        central = (residual(theta + h) - residual(theta - h)) / 2e-6
        assert np.allclose(jacobian[:, j], central, rtol=1e-5, atol=1e-6), j


def test_curve_fit_corrects_event_times_that_are_far_off(drogue_folder, tmp_path) -> None:
    """From events 0.3 s off, every stage's start guess lands within 0.1 s of the truth.

    The curve fit has no uncertainty of its own; 0.1 s (a third of the event
    error) separates a fit that found each rise from one that stayed at the
    event.  On seed 1 the largest error is 42 ms (a disreef, whose flat
    (t - t_i)^expopen start trades against n_p).
    """
    folder = drogue_folder(1)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    test = load_test(offset_events(folder, tmp_path / "test", START_GUESS_OFFSET_S))
    guess, _ = reduce_and_guess(test, Model(test, baseline_effects()))
    starts = [n for n in truth if n.startswith("t_start[")]
    errors = {n: abs(guess[n] - truth[n]) for n in starts}
    assert max(errors.values()) < 0.1, errors
