"""cpas-ocp montecarlo end to end: the FBCP test reconstructed and the dispersed cases of its
canopy stage flown through the fit, on local processes and on a Dask LocalCluster."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pandas as pd
import pytest
from scipy.stats import spearmanr

from cpas_ocp.campaign.campaign import COLUMNS
from cpas_ocp.campaign.peak_load_study import QUANTILES, match_cases, run_monte_carlo
from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.units import LBF

pytestmark = pytest.mark.slow

SEED = 7
LIMIT = 60
SHAPE = ("CdS", "Ck", "n_p", "expopen", "t_k")


@pytest.fixture(scope="module")
def study(problem_folder, tmp_path_factory):
    """The fbcp seed-1 folder, a dispersions folder drawn from 12 seeded tests scattered 5 %
    about its truth, and the command run on 2 local processes with the first 60 cases."""
    folder = problem_folder("fbcp", 1)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    root = tmp_path_factory.mktemp("montecarlo")
    rng = np.random.default_rng(SEED)
    rows = [{"test": f"t{k}", "parameter": b, "name": f"{b}[fbcp1,stage1]",
             "parachute": "fbcp1", "type": "fbcp", "stage": "stage1", "forebody": "capsule",
             "cluster_size": 2, "line_length": np.nan,
             "value": truth[f"{b}[fbcp1,stage1]"] * (1 + 0.05 * rng.standard_normal()),
             "std": 0.01, "unit": "1"} for k in range(12) for b in SHAPE]
    (root / "campaign").mkdir()
    pd.DataFrame(rows, columns=COLUMNS).to_parquet(root / "campaign" / "parameters.parquet")
    assert main(["dispersions", str(root / "campaign"), "--out", str(root / "dispersions"),
                 "--cases", "400", "--seed", str(SEED)]) == 0
    assert main(["montecarlo", str(folder), "--cases", str(root / "dispersions"), "--out",
                 str(root / "local"), "--limit", str(LIMIT), "--workers", "2"]) == 0
    return folder, root


def test_peak_loads_follow_peak_drag_area_times_dynamic_pressure(study) -> None:
    _, root = study
    cases = pd.read_parquet(root / "dispersions" / "cases_fbcp_stage1.parquet").iloc[:LIMIT]
    for chute in ("fbcp1", "fbcp2"):
        table = pd.read_parquet(root / "local" / f"peak_loads_{chute}_stage1.parquet")
        assert list(table.case) == list(range(LIMIT))
        pd.testing.assert_frame_equal(table[list(cases.columns)], cases)
        tension = table.peak_tension_N.to_numpy()
        np.testing.assert_allclose(table.peak_tension_lbf, tension / LBF, rtol=1e-12)
        # A rigid riser pulls T = CdS(t) q - W_p G: at the peak, the peak drag area Ck CdS
        # times a dynamic pressure that the dispersions barely move.  So T / (Ck CdS) is
        # nearly the same for every case while T itself spreads with the drag area.
        per_area = tension / (table.Ck * table.CdS).to_numpy()
        spread = per_area.std() / per_area.mean()
        assert spread < 0.1 * tension.std() / tension.mean(), spread
        assert spearmanr(tension, table.Ck * table.CdS)[0] > 0.99
        assert (table.peak_load_factor > 1.0).all()  # the pair decelerates the vehicle
        q = pd.read_csv(root / "local" / f"quantiles_{chute}_stage1.csv")
        assert list(q["quantile"]) == list(QUANTILES)
        assert np.all(np.diff(q.peak_tension_N) >= 0) and np.all(np.diff(q.peak_load_factor) >= 0)
        assert q.peak_tension_N.iloc[0] == tension.min()
        assert q.peak_tension_N.iloc[-1] == tension.max()
        np.testing.assert_allclose(q.peak_tension_lbf, q.peak_tension_N / LBF, rtol=1e-12)
        png = (root / "local" / f"peak_loads_{chute}_stage1.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert "fitted values peak at" in (root / "local" / "montecarlo.md").read_text()


def _bad(argv: list[str], capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_bad_input_is_one_line_exit_2_and_writes_nothing(study, tmp_path, capsys) -> None:
    folder, root = study
    out = tmp_path / "out"
    cases = root / "dispersions" / "cases_fbcp_stage1.parquet"
    err = _bad(["montecarlo", str(tmp_path / "missing"), "--cases", str(root / "dispersions"),
                "--out", str(out)], capsys)
    assert "manifest.json" in err
    (tmp_path / "drogues").mkdir()
    shutil.copy(cases, tmp_path / "drogues" / "cases_drogue_stage1.parquet")
    err = _bad(["montecarlo", str(folder), "--cases", str(tmp_path / "drogues"), "--out",
                str(out)], capsys)
    assert "cases_fbcp_stage1.parquet" in err and "cases_drogue_stage1.parquet" in err
    table = pd.read_parquet(cases)
    table.loc[5, "n_p"] = np.nan
    (tmp_path / "nan").mkdir()
    table.to_parquet(tmp_path / "nan" / "cases_fbcp_stage1.parquet")
    err = _bad(["montecarlo", str(folder), "--cases", str(tmp_path / "nan"), "--out", str(out)],
               capsys)
    assert "cases_fbcp_stage1.parquet: n_p: finite positive numbers; row 6" in err
    err = _bad(["montecarlo", str(folder), "--cases", str(root / "dispersions"), "--out",
                str(out), "--limit", "0"], capsys)
    assert "--limit" in err
    table = pd.read_parquet(cases).rename(columns={"n_p": "n"})
    (tmp_path / "finite").mkdir()
    table.to_parquet(tmp_path / "finite" / "cases_fbcp_stage1.parquet")
    err = _bad(["montecarlo", str(folder), "--cases", str(tmp_path / "finite"), "--out",
                str(out)], capsys)
    assert ": n: a parameter of fbcp1 stage1" in err
    assert not out.exists()


def test_a_worker_with_another_model_is_refused(study, tmp_path) -> None:
    """The workers rebuild the model from the folder's path: a copy that differs (here a
    vehicle 10 % heavier) flies the fitted values to another peak, and the run stops."""
    folder, root = study
    other = tmp_path / "other"
    shutil.copytree(folder, other)
    manifest = json.loads((other / "manifest.json").read_text())
    manifest["vehicle"]["mass"]["value"] *= 1.1
    (other / "manifest.json").write_text(json.dumps(manifest))
    fit = Estimator(load_test(folder)).solve()
    stages = match_cases(fit.test, root / "dispersions", limit=4)
    moved = dataclasses.replace(fit, test=dataclasses.replace(fit.test, path=other))
    with pytest.raises(InputError, match="the same model in every worker"):
        run_monte_carlo(moved, stages, workers=1)
    assert len(run_monte_carlo(fit, stages, workers=1)[0].loads.tension) == 4
