"""Drag-area envelopes (paper Figs. 18, 27): the inflation law drawn from a campaign's tables
is the model's own, and the Monte Carlo region holds the flight curves but not the extreme
corners the grown hull excludes."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign.campaign import STAGE_COLUMNS, reconstruct_folder
from cpas_ocp.campaign.dispersion_study import dispersion_models
from cpas_ocp.campaign.drag_area_envelope import cds_curves, drag_area_envelope, stage_conditions
from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.physics.inflation import CORNER_S
from cpas_ocp.physics.parameters import param_name
from tests.campaign.test_dispersion_study import SEED, _table

LAW = ("CdS", "Ck", "n_p", "expopen", "t_k")


def _compare_stage(q_cds: np.ndarray, t: np.ndarray, stages: pd.DataFrame,
                   table: pd.DataFrame, chute: str, stage: str, t_i: float,
                   t_end: float) -> None:
    """The law at the tables' conditions against the model's cds[chute] on [t_i, t_end)."""
    cond = stage_conditions(stages, table, "drogue" if "drogue" in chute else "fbcp", stage)
    rows = table[(table.parachute == chute) & (table.stage == stage)]
    params = pd.DataFrame([rows.set_index("parameter")["value"][list(LAW)]])
    window = (t >= t_i) & (t < t_end - CORNER_S)
    curve, _ = cds_curves(cond, params, t[window] - t_i)
    np.testing.assert_allclose(curve[0], q_cds[window], rtol=1e-9, atol=1e-9)


def test_law_from_the_tables_is_the_models_through_the_stages(problem_folder, tmp_path) -> None:
    """Drogue with growth-scaled fill lengths: stages 2 and 3 start from the previous stage's
    drag area and divide by the full-open one; each stage has its own start airspeed."""
    folder = tmp_path / "drogue"
    shutil.copytree(problem_folder("drogue", 1), folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    for chute in manifest["parachutes"]:
        chute["fill_length"] = "growth_scaled"
    (folder / "manifest.json").write_text(json.dumps(manifest))
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    test = load_test(folder)
    model = spec_of_test(test).model(test)
    chute = test.parachute("drogue1")
    speeds = {s: v for s, v in zip(chute.stages, (140.0, 110.0, 90.0), strict=True)}
    captured = {c.name: 100.0 for c in model.captures}
    captured.update({param_name("V_start", "drogue1", s): v for s, v in speeds.items()})
    t = np.linspace(test.t_start, test.t_end, 4001)
    x = np.zeros((t.size, model.nx))
    x[:, model.state_slice("velocity")] = [100.0, 0.0, -50.0]
    params = {**{p.name: p.default for p in model.parameters}, **truth}
    q_cds = model.quantities_along(t, x, params, captured)["cds[drogue1]"]
    table = pd.DataFrame([{"test": "t", "parachute": "drogue1", "type": "drogue", "stage": s,
                           "parameter": b, "value": truth[param_name(b, "drogue1", s)]}
                          for s in chute.stages for b in LAW])
    stages = pd.DataFrame([{"test": "t", "parachute": "drogue1", "type": "drogue", "stage": s,
                            "stage_index": k, "inflation": chute.inflation,
                            "fill_length": chute.fill_length, "diameter": chute.diameter,
                            "line_length": np.nan, "v_start": speeds[s]}
                           for k, s in enumerate(chute.stages)], columns=STAGE_COLUMNS)
    starts = [truth[param_name("t_start", "drogue1", s)] for s in chute.stages]
    for k, stage in enumerate(chute.stages):
        t_end = starts[k + 1] if k + 1 < len(starts) else test.t_end
        _compare_stage(q_cds, t, stages, table, "drogue1", stage, starts[k], t_end)


def test_campaign_tables_give_the_fitted_curve(problem_folder) -> None:
    """The rows a campaign writes for a test (parameters and stages.csv, with the captured
    start airspeed) redraw the fitted drag area of each canopy."""
    folder = problem_folder("fbcp", 1)
    outcome = reconstruct_folder(str(folder))
    assert outcome.ok
    table, stages = pd.DataFrame(outcome.rows), pd.DataFrame(outcome.stages)
    assert list(stages.columns) == STAGE_COLUMNS and (stages.v_start > 100.0).all()
    fit = Estimator(load_test(folder)).solve()
    q = fit.quantities()
    for chute in ("fbcp1", "fbcp2"):
        t_i = fit.parameters[param_name("t_start", chute, "stage1")]
        _compare_stage(q[f"cds[{chute}]"], fit.t, stages[stages.parachute == chute], table,
                       chute, "stage1", t_i, fit.t[-1])


def stage_table(table: pd.DataFrame) -> pd.DataFrame:
    """The stages table of the synthetic campaign `table`: drogues (D_o 7 m, infinite mass)
    and the other canopies (D_o 3 m, finite mass), one stage each, V_i 130 m/s."""
    kinds = table[["test", "parachute", "type"]].drop_duplicates()
    return pd.DataFrame([{"test": r.test, "parachute": r.parachute, "type": r.type,
                          "stage": "stage1", "stage_index": 0,
                          "inflation": "infinite_mass" if r.type == "drogue" else "finite_mass",
                          "fill_length": "diameter",
                          "diameter": {"drogue": 7.0}.get(r.type, 3.0),
                          "line_length": np.nan, "v_start": 130.0}
                         for r in kinds.itertuples()], columns=STAGE_COLUMNS)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The 25-test synthetic table of test_dispersion_study and its stages: drogues
    (D_o 7 m, infinite mass) and pilots (D_o 3 m, finite mass), V_i 130 m/s."""
    root = tmp_path_factory.mktemp("envelope")
    table = _table()
    table.to_parquet(root / "parameters.parquet", index=False)
    stage_table(table).to_csv(root / "stages.csv", index=False)
    assert main(["dispersions", str(root), "--out", str(root / "out"), "--cases", "4000",
                 "--seed", str(SEED)]) == 0
    return root


def test_envelope_holds_the_flights_and_excludes_the_extreme_corners(campaign) -> None:
    out = campaign / "out"
    models, _ = dispersion_models(_table())
    drogue = next(m for m in models if m.type == "drogue")
    stages = pd.read_csv(campaign / "stages.csv")
    cases = pd.read_parquet(out / "cases_drogue_stage1.parquet")
    env = drag_area_envelope(drogue, cases, stage_conditions(stages, _table(), "drogue",
                                                             "stage1"))
    bands = pd.read_csv(out / "envelope_drogue_stage1.csv")
    pd.testing.assert_frame_equal(bands, env.bands, check_exact=False, rtol=1e-12)
    # Once every case has settled, CdS(t) is the steady CdS: the band is the cases' range.
    assert bands["min"].iloc[-1] == pytest.approx(cases.CdS.min(), rel=1e-12)
    assert bands["max"].iloc[-1] == pytest.approx(cases.CdS.max(), rel=1e-12)
    # Each test point lies in the grown hull and the caps, so its curve lies in the region
    # the cases fill; 4,000 cases leave the sample's edge a little inside the region's
    # (0.05 % of the drag area at the worst point here; 0.1 % allowed).
    cds = drogue.test_points.CdS.median()
    assert env.flight_inside(tolerance=1e-3 * cds) == 1.0
    # The paper's extremes: high Ck with low n_p and expopen (the fastest, highest rise)
    # and the opposite corner lie outside the grown hull, and their curves leave the
    # Monte Carlo region by more than 1 % of the drag area, above and below.
    corners = dict(zip(env.corner_labels, env.corners, strict=True))
    inside = dict(zip(env.corner_labels, env.corner_inside, strict=True))
    high, low = corners["Ck+ n_p- expopen-"], corners["Ck- n_p+ expopen+"]
    assert inside["Ck+ n_p- expopen-"] is False and inside["Ck- n_p+ expopen+"] is False
    assert np.max(high - env.bands["max"].to_numpy()) > 0.01 * cds
    assert np.max(env.bands["min"].to_numpy() - low) > 0.01 * cds
    summary = json.loads((out / "dispersions.json").read_text())["models"]
    entry = {m["type"]: m for m in summary}
    assert entry["drogue"]["envelope"]["cases"] == 4000
    assert "Ck+ n_p- expopen-" in entry["drogue"]["envelope"]["corners_outside_hull"]
    # Pilots have no hull (expopen constant): their corners are the caps of n alone.
    assert entry["pilot"]["envelope"]["corners_outside_hull"] == []
    for name in ("envelope_drogue_stage1.png", "envelope_pilot_stage1.png",
                 "hull_drogue_stage1.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG", name


def test_without_a_stages_table_no_envelope_is_drawn(campaign, tmp_path, capsys) -> None:
    shutil.copy(campaign / "parameters.parquet", tmp_path / "parameters.parquet")
    assert main(["dispersions", str(tmp_path), "--out", str(tmp_path / "out"), "--cases",
                 "500", "--seed", "1"]) == 0
    assert "no stages.csv" in capsys.readouterr().out
    assert not list((tmp_path / "out").glob("envelope_*"))
