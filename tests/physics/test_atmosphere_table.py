"""A day-of-flight table atmosphere: read whole, interpolated as stated, and a long sounding
costs the model no more than a short one."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd

from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.atmosphere import StandardAtmosphere, TableAtmosphere, density_at, wind_at
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.model import Model


def _sounding(step_m: float = 300.0) -> pd.DataFrame:
    """A 0-33 km profile (111 rows at 300 m) with a wind shear, from the standard day."""
    h = np.arange(0.0, 33_000.0 + 1.0, step_m)
    rho = density_at(StandardAtmosphere(), h)
    return pd.DataFrame({"altitude": h, "density": rho, "wind_east": 5.0 + 1e-3 * h,
                         "wind_north": -2.0 + 5e-4 * h})


def _table(d: pd.DataFrame) -> TableAtmosphere:
    return TableAtmosphere(d["altitude"].to_numpy(), d["density"].to_numpy(),
                           d["wind_east"].to_numpy(), d["wind_north"].to_numpy())


def test_a_table_interpolates_log_density_and_wind_linearly() -> None:
    """At the rows the table's values; between them log(rho) and the wind linear; beyond the
    ends the end segments extended."""
    d = _sounding()
    table = _table(d)
    rows = d["altitude"].to_numpy()
    np.testing.assert_allclose(density_at(table, rows), d["density"], rtol=1e-12)
    middle = 0.5 * (rows[:-1] + rows[1:])
    np.testing.assert_allclose(np.log(density_at(table, middle)),
                               0.5 * (np.log(d["density"][:-1].to_numpy())
                                      + np.log(d["density"][1:].to_numpy())), rtol=1e-12)
    np.testing.assert_allclose(wind_at(table, middle)[:, :2],
                               np.column_stack([5.0 + 1e-3 * middle, -2.0 + 5e-4 * middle]),
                               rtol=1e-12)
    below, above = np.array([-600.0]), np.array([33_600.0])
    slope = np.diff(np.log(d["density"].to_numpy()[:2]))[0] / 300.0
    np.testing.assert_allclose(np.log(density_at(table, below)),
                               np.log(d["density"][0]) - 600.0 * slope, rtol=1e-12)
    np.testing.assert_allclose(wind_at(table, above)[0, 0], 5.0 + 1e-3 * 33_600.0, rtol=1e-12)


def test_a_long_sounding_costs_the_model_what_a_short_one_does(drogue_folder, tmp_path
                                                               ) -> None:
    """The table is a lookup in the model, not a branch per row: the model's dynamics hold
    as many operations with 441 rows as with 12, and the test folder keeps every row."""
    counts = {}
    for step_m in (3_000.0, 75.0):
        folder = tmp_path / f"test{step_m:g}"
        shutil.copytree(drogue_folder(1), folder)
        sounding = _sounding(step_m)
        sounding.to_csv(folder / "sounding.csv", index=False)
        manifest = json.loads((folder / "manifest.json").read_text())
        manifest["atmosphere"] = {"model": "table", "file": "sounding.csv", "columns": {
            "altitude": "m", "density": "kg/m^3", "wind_east": "m/s", "wind_north": "m/s"}}
        (folder / "manifest.json").write_text(json.dumps(manifest))
        test = load_test(folder)
        assert len(test.atmosphere.altitude_m) == len(sounding)
        counts[len(sounding)] = Model(test, baseline_effects()).rhs.n_instructions()
    assert set(counts) == {12, 441}
    assert counts[441] == counts[12]
