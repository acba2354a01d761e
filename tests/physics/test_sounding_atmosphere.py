"""A day-of-flight sounding with pressure: hydrostatic integration of a temperature
profile, the table read from CSV with one-line errors, and a barometric altimeter
reconstructed through it."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.atmosphere import (
    R_AIR,
    SoundingAtmosphere,
    StandardAtmosphere,
    density_at,
    hydrostatic_pressure,
)
from cpas_ocp.physics.units import G0


def _numeric(f, h: np.ndarray) -> np.ndarray:
    return np.array([float(f(x)) for x in h])


def _standard_temperature(h: np.ndarray) -> np.ndarray:
    return 288.15 - 0.0065 * np.minimum(h, 11_000.0)


def test_hydrostatic_integration_reproduces_the_standard_pressure() -> None:
    """The standard day's temperature every 250 m from 0 to 20 km, integrated from the
    standard sea-level pressure, gives the standard pressure (the analytic U.S. 1976
    layers) at the rows to rounding, and between them within the log-linear
    interpolation's bound: ln p has curvature g0 L / (R T^2), so a chord over a row step
    dh departs from it by at most dh^2/8 times that (L = 6.5 K/km, T >= 216.65 K)."""
    step = 250.0
    h = np.arange(0.0, 20_000.0 + 1.0, step)
    table = SoundingAtmosphere.from_profile(h, temperature_k=_standard_temperature(h))
    std = StandardAtmosphere()
    np.testing.assert_allclose(table.pressure_pa, _numeric(std.pressure, h), rtol=1e-12)
    np.testing.assert_allclose(density_at(table, h), density_at(std, h), rtol=1e-12)
    middle = h[:-1] + 0.5 * step
    bound = step**2 / 8.0 * G0 * 0.0065 / (R_AIR * 216.65**2)
    error = np.abs(np.log(_numeric(table.pressure, middle) / _numeric(std.pressure, middle)))
    assert error.max() < bound
    assert error.max() > 0.1 * bound  # the bound is the interpolation's, not a loose one
    # The altimeter's inverse is the interpolation's exact inverse, beyond the rows too.
    for x in (middle, np.array([-300.0, 20_400.0])):
        np.testing.assert_allclose(table.altitude_at_pressure(_numeric(table.pressure, x)), x,
                                   atol=1e-6)


def test_an_isothermal_layer_and_a_given_base_pressure() -> None:
    """An inversion, then an isothermal layer: each layer's exact solution from the given
    base pressure, and the density from the gas law."""
    h = np.array([1000.0, 1500.0, 2500.0])
    temp = np.array([280.0, 284.0, 284.0])
    p = hydrostatic_pressure(h, temp, 90_000.0)
    lapse = -4.0 / 500.0
    p1 = 90_000.0 * (284.0 / 280.0) ** (G0 / (R_AIR * lapse))
    p2 = p1 * np.exp(-G0 * 1000.0 / (R_AIR * 284.0))
    np.testing.assert_allclose(p, [90_000.0, p1, p2], rtol=1e-12)
    table = SoundingAtmosphere.from_profile(h, temperature_k=temp, base_pressure_pa=90_000.0)
    np.testing.assert_allclose(table.density_kg_m3, p / (R_AIR * temp), rtol=1e-12)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """rocket_steady seed 1, made through its site atmosphere (with truth.json)."""
    folder = tmp_path_factory.mktemp("sounding") / "sim"
    simulate_problem(load_problem("rocket_steady"), folder, 1)
    return folder


def _folder(simulated: Path, tmp_path: Path, table: pd.DataFrame, columns: dict, **extra
            ) -> Path:
    """A copy of `simulated` without truth.json whose atmosphere is `table` (sounding.csv)."""
    folder = tmp_path / "test"
    shutil.copytree(simulated, folder, ignore=shutil.ignore_patterns("truth.json"))
    table.to_csv(folder / "sounding.csv", index=False)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["atmosphere"] = {"model": "table", "file": "sounding.csv", "columns": columns,
                              **extra}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def _site_sounding() -> tuple[pd.DataFrame, float]:
    """The rocket_steady site atmosphere sampled as a sounding every 100 m (hPa, K), and
    its pressure at the first row (hPa)."""
    atm = load_problem("rocket_steady").manifest["atmosphere"]
    h0, p0, t0 = atm["elevation"]["value"], atm["pressure"]["value"], atm["temperature"]["value"]
    lapse = atm["lapse_rate"]["value"] * 1e-3
    h = np.arange(1300.0, 3000.0 + 1.0, 100.0)
    temp = t0 - lapse * (h - h0)
    p = p0 * (temp / t0) ** (G0 / (R_AIR * lapse))
    return pd.DataFrame({"altitude": h, "pressure": p / 100.0, "temperature": temp}), p[0] / 100


@pytest.mark.parametrize("pressure_column", [True, False])
def test_a_baro_reconstruction_through_a_sounding(simulated: Path, tmp_path: Path,
                                                  pressure_column: bool) -> None:
    """rocket_steady (made through its site atmosphere), reconstructed through the same
    air given as a sounding table: with its pressure column, or with temperature alone
    integrated from the first row's pressure.  The drag areas within 4 sigma of the
    truth."""
    sounding, p_first = _site_sounding()
    columns = {"altitude": "m", "pressure": "hPa", "temperature": "K"}
    extra = {}
    if not pressure_column:
        sounding = sounding.drop(columns="pressure")
        columns.pop("pressure")
        extra = {"surface_pressure": {"value": p_first, "unit": "hPa"}}
    test = load_test(_folder(simulated, tmp_path, sounding, columns, **extra))
    assert isinstance(test.atmosphere, SoundingAtmosphere)
    truth = json.loads((simulated / "truth.json").read_text())["parameters"]
    est = Estimator(test)
    fit = est.solve()
    cov = est.covariance(fit)
    for name in ("CdS[drogue,stage1]", "CdS[main,stage2]"):
        z = (fit.parameters[name] - truth[name]) / cov.std[name]
        assert abs(z) < 4.0, f"{name}: {z:+.2f} sigma"


@pytest.mark.parametrize(("change", "field"), [
    (lambda d, c, e: c.pop("temperature"), "atmosphere.columns"),
    (lambda d, c, e: d.__setitem__("pressure", d["pressure"][::-1].to_numpy()), "pressure"),
    (lambda d, c, e: d.__setitem__("temperature", -d["temperature"]), "temperature"),
    (lambda d, c, e: e.__setitem__("surface_pressure", {"value": 900, "unit": "hPa"}),
     "atmosphere.surface_pressure"),
    (lambda d, c, e: c.__setitem__("temperature", "degC"), "atmosphere.columns.temperature"),
    (lambda d, c, e: d.iloc[:1], "altitude"),
])
def test_a_bad_sounding_is_refused_in_one_line(simulated: Path, tmp_path: Path, change,
                                               field: str) -> None:
    """Pressure alone, pressure rising with altitude, a temperature not positive, a
    surface pressure beside a pressure column, a unit not accepted, a single row (nothing
    to interpolate between): InputError naming the field."""
    sounding, _ = _site_sounding()
    columns = {"altitude": "m", "pressure": "hPa", "temperature": "K"}
    extra: dict = {}
    changed = change(sounding, columns, extra)
    if isinstance(changed, pd.DataFrame):  # a change that makes a new table
        sounding = changed
    folder = _folder(simulated, tmp_path, copy.deepcopy(sounding), columns, **extra)
    with pytest.raises(InputError) as err:
        load_test(folder)
    assert err.value.field == field
