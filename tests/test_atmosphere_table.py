"""A day-of-flight table atmosphere: a long sounding costs the fit only the rows it flies."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.atmosphere import StandardAtmosphere, TableAtmosphere, density_at, wind_at
from cpas_ocp.flight_test import ATMOSPHERE_MARGIN_M, load_test


def _sounding(step_m: float = 300.0) -> pd.DataFrame:
    """A 0-33 km profile (111 rows at 300 m) with a wind shear, from the standard day."""
    h = np.arange(0.0, 33_000.0 + 1.0, step_m)
    rho = density_at(StandardAtmosphere(), h)
    return pd.DataFrame({"altitude": h, "density": rho, "wind_east": 5.0 + 1e-3 * h,
                         "wind_north": -2.0 + 5e-4 * h})


def _table(d: pd.DataFrame) -> TableAtmosphere:
    return TableAtmosphere(d["altitude"].to_numpy(), d["density"].to_numpy(),
                           d["wind_east"].to_numpy(), d["wind_north"].to_numpy())


def test_a_table_cut_to_a_band_is_the_same_profile_inside_it() -> None:
    full = _table(_sounding())
    cut = full.within(6_950.0, 8_020.0)
    # The last row at or below the band's floor to the first at or above its top.
    np.testing.assert_array_equal(cut.altitude_m, np.arange(6_900.0, 8_100.0 + 1, 300.0))
    h = np.linspace(6_950.0, 8_020.0, 57)
    np.testing.assert_allclose(density_at(cut, h), density_at(full, h), rtol=1e-12)
    np.testing.assert_allclose(wind_at(cut, h), wind_at(full, h), rtol=1e-12, atol=1e-12)
    assert full.within(-1e4, 1e5) is full


def test_a_test_folder_keeps_the_rows_its_sensors_fly_through(drogue_folder, tmp_path) -> None:
    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    sounding = _sounding()
    sounding.to_csv(folder / "sounding.csv", index=False)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["atmosphere"] = {"model": "table", "file": "sounding.csv", "columns": {
        "altitude": "m", "density": "kg/m^3", "wind_east": "m/s", "wind_north": "m/s"}}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    test = load_test(folder)
    up = np.concatenate([s.data["up"].to_numpy() for s in test.sensors if s.kind == "gps"])
    lo, hi = up.min() - ATMOSPHERE_MARGIN_M, up.max() + ATMOSPHERE_MARGIN_M
    kept = test.atmosphere.altitude_m
    assert kept[0] <= lo < kept[1] and kept[-2] < hi <= kept[-1]
    assert len(kept) < len(sounding) / 2
    h = np.linspace(up.min(), up.max(), 101)
    np.testing.assert_allclose(density_at(test.atmosphere, h),
                               density_at(_table(sounding), h), rtol=1e-12)


@pytest.mark.parametrize("band", [(-500.0, 100.0), (32_900.0, 40_000.0)])
def test_a_band_at_the_table_s_end_keeps_a_segment(band) -> None:
    cut = _table(_sounding()).within(*band)
    assert len(cut.altitude_m) >= 2
