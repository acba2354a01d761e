"""A 95 % interval far wider than the bounds it lies in is no interval: a start time of
11.461 ± 13.62 s, [-15.2, 38.2], inside a start window of 4 s is undetermined within its
window, and the reports say so (result.json keeps the numbers and a flag)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from cpas_ocp.reports.report import parameter_table, write_report


def _widened(fit, cov, name: str, factor: float):
    """`cov` with the variance of `name` set to (`factor` x the width of its bounds)^2."""
    prm = fit.model.parameter(name)
    matrix = np.array(cov.matrix, copy=True)
    i = cov.names.index(name)
    matrix[i, i] = (factor * (prm.upper - prm.lower)) ** 2
    return dataclasses.replace(cov, matrix=matrix)


def test_a_start_time_wider_than_its_window_is_undetermined_within_it(drogue_fit,
                                                                      tmp_path) -> None:
    fit, cov, _ = drogue_fit(1)
    name = next(n for n in fit.free if n.startswith("t_start") and n not in cov.at_bound)
    prm = fit.model.parameter(name)
    wide = _widened(fit, cov, name, 3.0)
    said = f"undetermined within its window [{prm.lower:.5g}, {prm.upper:.5g}]"
    out = write_report(fit, wide, tmp_path / "report")
    terminal = parameter_table(fit, wide)
    for text in (terminal, (out / "report.md").read_text()):
        [line] = [line for line in text.splitlines() if line.startswith(f"{name} ")]
        assert said in line and "[" not in line.replace(name, "").replace(said, ""), line
        # The others keep their intervals.
        other = next(n for n in fit.free if n != name and n in cov.std)
        [line] = [line for line in text.splitlines() if line.startswith(f"{other} ")]
        assert "undetermined within" not in line and "[" in line.replace(other, ""), line
    page = (out / "report.html").read_text()
    assert f"<tr class=flagged><td>{name}</td>" in page and f"<td>{said}</td>" in page
    entry = json.loads((out / "result.json").read_text())["parameters"][name]
    assert entry["undetermined_within_bounds"] is True
    assert entry["std"] == wide.std[name] and len(entry["ci95"]) == 2
    assert entry["bounds"] == [prm.lower, prm.upper]
    # Its sigma within the window: an interval as before, and the flag false.
    narrow = _widened(fit, cov, name, 0.5)
    [line] = [line for line in parameter_table(fit, narrow).splitlines()
              if line.startswith(f"{name} ")]
    assert "undetermined within" not in line and "[" in line.replace(name, "")
