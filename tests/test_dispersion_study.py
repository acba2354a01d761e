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
