"""`cpas-ocp reduce`: the offline reduction's outputs and the guess it hands the estimator."""

from __future__ import annotations

import json

import pandas as pd

from cpas_ocp.cli import main
from cpas_ocp.effects import baseline_effects
from cpas_ocp.flight_test import load_test
from cpas_ocp.model import Model

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


def test_reduce_refuses_a_foreign_folder(drogue_folder, tmp_path, capsys):
    out = tmp_path / "not-a-reduction"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert main(["reduce", str(drogue_folder(1)), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "initial_guess.json" in err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
