"""Display units: figures and tables follow the manifest's unit system or --units; result.json
stays SI."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.units import FACTORS, FT, LB, LBF, dimension_of
from cpas_ocp.precision import rounded, sigma_text
from cpas_ocp.reports.display_units import (
    US_CUSTOMARY,
    DisplayUnits,
    display_units,
    manifest_system,
)
from cpas_ocp.reports.report import fit_summary, parameter_table, result_dict, write_report


def _si(node: Any) -> Any:
    """A manifest with every US customary {value, unit} quantity restated in SI."""
    if isinstance(node, dict):
        if node.get("unit") in US_CUSTOMARY and "value" in node:
            dim = dimension_of(node["unit"], tuple(FACTORS))
            si = next(u for u, f in FACTORS[dim].items() if f == 1.0)
            return {**node, "value": node["value"] * FACTORS[dim][node["unit"]], "unit": si}
        return {k: _si(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_si(v) for v in node]
    return node


def si_folder(folder: Path, dest: Path) -> Path:
    """A copy of a test folder written wholly in SI: quantities, and series files with
    their columns converted."""
    shutil.copytree(folder, dest)
    manifest = _si(json.loads((dest / "manifest.json").read_text()))
    for sensor in manifest["sensors"]:
        frame = pd.read_csv(dest / sensor["file"])
        for column, unit in sensor["columns"].items():
            if unit in US_CUSTOMARY:
                dim = dimension_of(unit, tuple(FACTORS))
                frame[column] *= FACTORS[dim][unit]
                sensor["columns"][column] = next(
                    u for u, f in FACTORS[dim].items() if f == 1.0)
        frame.to_csv(dest / sensor["file"], index=False)
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return dest


def test_the_system_is_read_from_the_manifest_quantities() -> None:
    drogue = load_problem("drogue").manifest
    assert manifest_system(drogue) == "us"  # lb, ft, ft^2, lbf (sigmas in m)
    assert manifest_system(_si(drogue)) == "si"
    # A rocket given in kg and m with its canopies' diameters in inches reads SI.
    assert manifest_system(load_problem("rocket_gusts").manifest) == "si"
    assert manifest_system({}) == "si"  # nothing stated: SI


def test_conversions_are_the_physics_factors() -> None:
    us, si = DisplayUnits("us"), DisplayUnits("si")
    assert us.channel("tension") == ("lbf", pytest.approx(1 / LBF))
    assert us.channel("v_up") == ("ft/s", pytest.approx(1 / FT))
    assert us.channel("altitude") == ("ft", pytest.approx(1 / FT))
    assert us.channel("load_factor") == ("g", 1.0) == si.channel("load_factor")
    assert si.channel("tension") == ("N", 1.0)
    assert us.of_si("m^2") == ("ft^2", pytest.approx(1 / FT**2))
    assert us.of_si("kg") == ("lb", pytest.approx(1 / LB))
    assert us.of_si("s") == ("s", 1.0) and us.of_si("1") == ("1", 1.0)
    assert si.of_si("N/m") == ("N/m", 1.0)
    with pytest.raises(ValueError, match="unit system"):
        DisplayUnits("imperial")


def test_an_si_manifest_gives_si_tables_and_figures(drogue_fit, tmp_path) -> None:
    fit, cov, _ = drogue_fit(1)
    si_test = dataclasses.replace(fit.test, manifest=_si(fit.test.manifest))
    fit_si = dataclasses.replace(fit, test=si_test)
    assert display_units(si_test).system == "si" and display_units(fit.test).system == "us"
    table, summary = parameter_table(fit_si, cov), fit_summary(fit_si)
    row = next(line for line in table.splitlines() if line.startswith("CdS[drogue1,stage1]"))
    assert " m^2 " in row and "ft" not in table
    assert float(row.split()[1]) == pytest.approx(fit.parameters["CdS[drogue1,stage1]"],
                                                  rel=1e-4)
    assert "tension" in summary and " N" in summary and "lbf" not in summary
    out = write_report(fit_si, cov, tmp_path / "report")
    page = (out / "report.html").read_text()
    # (plotly's JSON writes ² as \u00b2)
    assert "tension [N]" in page and "CdS [m\\u00b2]" in page
    assert "tension [lbf]" not in page and "CdS [ft" not in page and "east [ft]" not in page
    assert "in SI units, as the manifest is written" in page
    # result.json is SI whichever the display.
    assert json.loads((out / "result.json").read_text())["parameters"] == json.loads(
        json.dumps(result_dict(fit, cov)["parameters"]))


def test_us_table_converts_the_si_values(drogue_fit) -> None:
    fit, cov, _ = drogue_fit(1)
    table = parameter_table(fit, cov, DisplayUnits("us"))
    name = "CdS[drogue1,stage1]"
    row = next(line for line in table.splitlines() if line.startswith(name))
    value, std = row.split()[1:3]
    assert " ft^2 " in row
    # converted, then rounded to two digits of the converted sigma
    assert std == sigma_text(cov.std[name] / FT**2)
    assert value == rounded(fit.parameters[name] / FT**2, cov.std[name] / FT**2)


@pytest.mark.slow
def test_units_option_overrides_an_si_manifest(drogue_folder, tmp_path, capsys) -> None:
    folder = si_folder(drogue_folder(1), tmp_path / "test")
    out = tmp_path / "report"
    code = main(["reconstruct", str(folder), "--out", str(out), "--units", "us"])
    printed = capsys.readouterr().out
    assert code == 0
    assert f"interactive report: {out / 'report.html'}" in printed
    row = next(line for line in printed.splitlines() if line.startswith("CdS[drogue1,stage1]"))
    assert " ft^2 " in row and "lbf" in printed and "tension" in printed
    page = (out / "report.html").read_text()
    assert "tension [lbf]" in page and "CdS [ft\\u00b2]" in page
    assert "as asked (the manifest is written in SI)" in page
    assert "ft^2" in (out / "report.md").read_text()
    result = json.loads((out / "result.json").read_text())
    assert result["parameters"]["CdS[drogue1,stage1]"]["unit"] == "m^2"


def test_reduce_prints_the_guess_in_the_units_asked(drogue_folder, tmp_path, capsys) -> None:
    folder = drogue_folder(1)
    assert main(["reduce", str(folder), "--out", str(tmp_path / "us")]) == 0
    us = capsys.readouterr().out
    assert main(["reduce", str(folder), "--out", str(tmp_path / "si"), "--units", "si"]) == 0
    si = capsys.readouterr().out
    name = "CdS[drogue1,stage1]"
    row_us, row_si = (next(line for line in text.splitlines() if line.startswith(name))
                      for text in (us, si))
    assert row_us.split()[2] == "ft^2" and row_si.split()[2] == "m^2"
    assert float(row_us.split()[1]) * FT**2 == pytest.approx(float(row_si.split()[1]),
                                                             rel=1e-4)
    guess = json.loads((tmp_path / "si" / "initial_guess.json").read_text())["parameters"]
    assert guess[name]["unit"] == "m^2"  # the file stays SI
    assert guess[name]["value"] == pytest.approx(float(row_si.split()[1]), rel=1e-4)
