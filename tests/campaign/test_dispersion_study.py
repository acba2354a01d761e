"""Monte Carlo inputs from a campaign table: per canopy type and stage, capped dispersions
and the grown hull of the inflation parameters; reproducible by seed."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign.campaign import COLUMNS
from cpas_ocp.campaign.dispersion_study import dispersion_models
from cpas_ocp.cli import main

SEED = 11


def _table() -> pd.DataFrame:
    """25 tests of drogues (infinite mass: Ck, n_p, expopen, t_k, CdS), pilots with expopen
    held at 1 (finite mass: n, CdS), and three mains (too few to disperse)."""
    rng = np.random.default_rng(SEED)
    rows = []

    def add(test, chute, kind, values):
        for base, value in values.items():
            rows.append({"test": test, "parameter": base, "name": f"{base}[{chute},stage1]",
                         "parachute": chute, "type": kind, "stage": "stage1",
                         "forebody": "vehicle", "cluster_size": 1, "value": value, "std": 0.01,
                         "unit": "1"})
    for k in range(25):
        add(f"d{k}", "drogue1", "drogue", {
            "CdS": rng.normal(21.0, 0.6), "Ck": rng.normal(1.15, 0.04),
            "n_p": rng.lognormal(np.log(6.0), 0.1), "expopen": rng.uniform(1.1, 1.6),
            "t_k": rng.normal(0.4, 0.03), "t_start": rng.uniform(10, 13)})
        add(f"p{k}", "pilot1", "pilot", {"CdS": rng.normal(5.5, 0.2), "n": rng.normal(8, 0.5),
                                         "expopen": 1.0})
    for k in range(3):
        add(f"m{k}", "main1", "main", {"CdS": rng.normal(500, 10), "n": rng.normal(10, 1),
                                       "expopen": rng.normal(1.2, 0.1)})
    return pd.DataFrame(rows, columns=COLUMNS)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("dispersions")
    _table().to_parquet(root / "parameters.parquet", index=False)
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        assert main(["dispersions", str(root), "--out", str(root / name), "--cases", "20000",
                     "--seed", str(seed)]) == 0
    return root


def test_models_per_type_and_stage() -> None:
    models, skipped = dispersion_models(_table())
    by = {m.type: m for m in models}
    assert set(by) == {"drogue", "pilot"} and len(skipped) == 1 and skipped[0].startswith("main")
    assert by["drogue"].hull_names == ("Ck", "n_p", "expopen")
    assert by["drogue"].hull.growth == pytest.approx(0.10)
    assert "t_start" not in by["drogue"].dispersions
    # A pilot's expopen is constant over the tests: not dispersed, and no 2-D hull is left.
    assert "expopen" not in by["pilot"].dispersions and by["pilot"].hull is None


def test_cases_lie_in_the_grown_hull_and_the_caps(written) -> None:
    models, _ = dispersion_models(_table())
    drogue = next(m for m in models if m.type == "drogue")
    cases = pd.read_parquet(written / "a" / "cases_drogue_stage1.parquet")
    assert len(cases) == 20000
    assert drogue.hull.contains(cases[list(drogue.hull_names)].to_numpy()).all()
    for name, d in drogue.dispersions.items():
        assert cases[name].between(d.lower_cap, d.upper_cap).all(), name
    # The corner of the caps box with every shape parameter at its upper cap lies outside
    # the grown hull: no case may sit there.
    corner = np.array([drogue.dispersions[k].upper_cap for k in drogue.hull_names])
    assert not drogue.hull.contains(corner[None, :])[0]
    summary = json.loads((written / "a" / "dispersions.json").read_text())
    assert {m["type"] for m in summary["models"]} == {"drogue", "pilot"}
    for name in ("hull_drogue_stage1.png", "histograms_drogue_stage1.png",
                 "histograms_pilot_stage1.png"):
        assert (written / "a" / name).is_file(), name


def test_cases_are_reproducible_by_seed(written) -> None:
    a = pd.read_parquet(written / "a" / "cases_drogue_stage1.parquet")
    b = pd.read_parquet(written / "b" / "cases_drogue_stage1.parquet")
    c = pd.read_parquet(written / "c" / "cases_drogue_stage1.parquet")
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a.to_numpy(), c.to_numpy())


def test_missing_table_is_one_line_exit_2(tmp_path, capsys) -> None:
    assert main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--seed", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "parameters.parquet" in err


def _collinear(table: pd.DataFrame) -> pd.DataFrame:
    """The drogues' n_p and expopen moved onto a line through their Ck: no 3-D hull."""
    table = table.copy()
    for test, ck in table[table.parameter == "Ck"].set_index("test")["value"].items():
        if not str(test).startswith("d"):
            continue
        rows = table.test == test
        table.loc[rows & (table.parameter == "n_p"), "value"] = 6.0 + 10.0 * (ck - 1.15)
        table.loc[rows & (table.parameter == "expopen"), "value"] = 1.3 + 2.0 * (ck - 1.15)
    return table


def _cell(table: pd.DataFrame, row: int, column: str, value: object) -> pd.DataFrame:
    table = table.astype({column: object})
    table.loc[row, column] = value
    return table


# A damaged campaign table: what its CSV holds, and what the one line names.
BAD_TABLES = {
    "a negative drag area": (lambda t: _cell(t, 0, "value", -21.0), "line 2, value"),
    "a negative fill constant": (lambda t: _cell(t, 3, "value", -6.0), "line 5, value"),
    "a text cell": (lambda t: _cell(t, 3, "value", "x"), "line 5, value"),
    "an infinite value": (lambda t: _cell(t, 3, "value", np.inf), "line 5, value"),
    "a blank value": (lambda t: _cell(t, 3, "value", np.nan), "line 5, value"),
    "a cluster of no canopies": (lambda t: _cell(t, 4, "cluster_size", 0), "line 6, "
                                 "cluster_size"),
    "a negative line length": (lambda t: _cell(t, 4, "line_length", -3.0), "line 6, "
                               "line_length"),
    "no unit column": (lambda t: t.drop(columns="unit"), "unit"),
}


@pytest.mark.parametrize("case", list(BAD_TABLES))
def test_a_damaged_campaign_table_is_one_line(case, tmp_path, capsys) -> None:
    """Drag areas, fill constants and the other dispersed parameters are positive; a cell
    that is no number, or a column that is missing, is one line naming the file, its line
    and column, exit 2, nothing written (a negative drag area was dispersed, a text cell
    ended in a TypeError)."""
    damage, named = BAD_TABLES[case]
    damage(_table()).to_csv(tmp_path / "parameters.csv", index=False)
    code = main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "100",
                 "--seed", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "parameters.csv" in err[0] and named in err[0], err
    assert not (tmp_path / "o").exists()


# A Parquet table holds numbers as numbers: what a damaged one holds, and the one line.
BAD_PARQUET = {
    "values written as text": (lambda t: t.astype({"value": str}), "row 1, value",
                               "not text"),
    "a value beyond 1e9": (lambda t: _cell(t, 3, "value", 5e9), "row 4, value", "at most 1e+09"),
    "a std beyond 1e9": (lambda t: _cell(t, 2, "std", -2e12), "row 3, std", "at most 1e+09"),
    "a cluster size as text": (lambda t: t.astype({"cluster_size": str}), "row 1, cluster_size",
                               "not text"),
}


@pytest.mark.parametrize("case", list(BAD_PARQUET))
def test_a_damaged_parquet_table_is_one_line(case, tmp_path, capsys) -> None:
    """Text in a column of numbers, or a number beyond any test's, in parameters.parquet:
    one line naming the file, the row and the column, and what was expected; exit 2,
    nothing written (both were dispersed, exit 0)."""
    damage, named, expected = BAD_PARQUET[case]
    damage(_table()).to_parquet(tmp_path / "parameters.parquet", index=False)
    code = main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "100",
                 "--seed", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"parameters.parquet: {named}: " in err[0] and expected in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_csv_value_beyond_1e9_is_one_line(tmp_path, capsys) -> None:
    """A CSV's cells are text that reads as numbers; one beyond 1e9 is refused like a
    Parquet table's."""
    _cell(_table(), 3, "value", 5e9).to_csv(tmp_path / "parameters.csv", index=False)
    code = main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "100",
                 "--seed", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "parameters.csv: line 5, value: " in err[0], err


def test_a_negative_diameter_in_the_stages_table_is_one_line(tmp_path, capsys) -> None:
    _table().to_csv(tmp_path / "parameters.csv", index=False)
    pd.DataFrame([{"test": "d0", "parachute": "drogue1", "type": "drogue", "stage": "stage1",
                   "stage_index": 0, "inflation": "infinite_mass", "fill_length": "diameter",
                   "diameter": -5.0, "line_length": np.nan, "v_start": 80.0}]).to_csv(
        tmp_path / "stages.csv", index=False)
    code = main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "100",
                 "--seed", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "stages.csv: line 2, diameter" in err, err
    assert not (tmp_path / "o").exists()


def test_collinear_shape_parameters_leave_the_caps_to_bound_the_draws(tmp_path, capsys) -> None:
    """Tests whose (Ck, n_p, expopen) lie on a line have no hull with a volume: the drogue is
    dispersed within its caps, and the summary says why there is no hull (it ended in an
    internal error)."""
    _collinear(_table()).to_csv(tmp_path / "parameters.csv", index=False)
    assert main(["dispersions", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "100",
                 "--seed", "1"]) == 0
    assert "collinear" in capsys.readouterr().out
    assert (tmp_path / "o" / "cases_drogue_stage1.parquet").is_file()
