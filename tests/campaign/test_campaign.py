"""A campaign over a small generated set of tests: mixed parachute types and one broken
folder, on local processes and on a Dask LocalCluster."""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from cpas_ocp.campaign.campaign import COLUMNS
from cpas_ocp.cli import main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def tests_root(problem_folder, tmp_path_factory):
    """fbcp seeds 1 and 2 (suspension lines 14 ft and 10.5 ft: L_s/D_o 2.0 and 1.5), pilot
    seed 1 (no line length), and fbcp seed 1 with a NaN run in its IMU series."""
    root = tmp_path_factory.mktemp("campaign")
    for name, seed in (("fbcp", 1), ("fbcp", 2), ("pilot", 1)):
        shutil.copytree(problem_folder(name, seed), root / f"{name}{seed}")
        (root / f"{name}{seed}" / "truth.json").unlink()
    for seed, feet in ((1, 14.0), (2, 10.5)):
        path = root / f"fbcp{seed}" / "manifest.json"
        manifest = json.loads(path.read_text())
        for chute in manifest["parachutes"]:
            chute["line_length"] = {"value": feet, "unit": "ft"}
        path.write_text(json.dumps(manifest))
    shutil.copytree(root / "fbcp1", root / "broken")
    imu = pd.read_csv(root / "broken" / "imu.csv", comment="#")
    imu.iloc[50:60, 1] = float("nan")
    imu.to_csv(root / "broken" / "imu.csv", index=False)
    return root


def test_campaign_tabulates_every_test_and_reports_the_broken_one(tests_root, tmp_path,
                                                                  capsys) -> None:
    out = tmp_path / "out"
    assert main(["campaign", str(tests_root), "--out", str(out), "--workers", "2"]) == 0
    captured = capsys.readouterr()
    assert "1 of 4 tests failed" in captured.err
    table = pd.read_parquet(out / "parameters.parquet")
    assert list(table.columns) == COLUMNS
    assert sorted(table.test.unique()) == ["fbcp-seed1", "fbcp-seed2", "pilot-seed1"]
    assert set(table.type) >= {"fbcp", "pilot"}
    fbcp = table[(table.test == "fbcp-seed1") & (table.name == "CdS[fbcp1,stage1]")].iloc[0]
    assert (fbcp.parachute, fbcp.stage, fbcp.cluster_size, fbcp.unit) == ("fbcp1", "stage1", 2,
                                                                         "m^2")
    assert fbcp["std"] > 0.0
    assert pd.read_csv(out / "parameters.csv").shape == table.shape
    failures = pd.read_csv(out / "failures.csv")
    assert list(failures.test) == ["broken"] and list(failures.kind) == ["input"]
    assert "imu.csv" in failures.message[0] and "rows 51-60" in failures.message[0]
    ratios = pd.read_csv(out / "ratios_cluster_size.csv")
    assert set(ratios.type) == {"fbcp", "pilot"} and (ratios.ratio == 1.0).all()
    # The manifests' line lengths, in m, on the canopies' rows; empty for the pilot test.
    lengths = table[table.parachute.notna() & (table.parachute != "")].groupby(
        "test").line_length.unique()
    assert list(lengths["fbcp-seed1"]) == [round(14 * 0.3048, 4)]
    assert list(lengths["fbcp-seed2"]) == [round(10.5 * 0.3048, 4)]
    assert table[table.test == "pilot-seed1"].line_length.isna().all()
    by_length = pd.read_csv(out / "ratios_line_length.csv")
    assert set(by_length.type) == {"fbcp"} and list(by_length.tests) == [2, 2]
    assert (out / "ratios_cluster_size_by_line_length.csv").is_file()
    stages = pd.read_csv(out / "stages.csv")
    assert len(stages) == 2 + 2 + len(stages[stages.test == "pilot-seed1"])
    assert (stages.v_start > 0).all() and set(stages.inflation) == {"infinite_mass",
                                                                     "finite_mass"}
    # Each test's covariance: its diagonal is the table's std squared, one row per pair.
    cov = pd.read_csv(out / "covariances.csv")
    assert sorted(cov.test.unique()) == sorted(table.test.unique())
    diagonal = cov[cov.name_a == cov.name_b].merge(table, left_on=["test", "name_a"],
                                                   right_on=["test", "name"])
    assert len(diagonal) == table["std"].notna().sum()
    assert (abs(diagonal.covariance - diagonal["std"] ** 2) <= 1e-9 * diagonal.covariance).all()
    one = cov[cov.test == "fbcp-seed1"]
    assert len(one) == len(diagonal[diagonal.test == "fbcp-seed1"]) * (
        len(diagonal[diagonal.test == "fbcp-seed1"]) + 1) // 2


def test_no_test_folders_is_one_line_exit_2(tmp_path, capsys) -> None:
    assert main(["campaign", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "manifest.json" in err


def test_a_campaign_without_one_result_is_a_failure(tests_root, tmp_path, capsys) -> None:
    """Every test failing is no campaign: exit 3 with one line, the reasons in failures.csv."""
    only = tmp_path / "tests"
    shutil.copytree(tests_root / "broken", only / "broken")
    out = tmp_path / "out"
    assert main(["campaign", str(only), "--out", str(out), "--workers", "1"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.splitlines()[-1].startswith("error: every one of the 1 tests failed"), err
    assert list(pd.read_csv(out / "failures.csv").test) == ["broken"]
