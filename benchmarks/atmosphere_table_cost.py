"""Benchmark: the cost of a fit with a long day-of-flight sounding, whole against cut.

The `drogue` problem (seed 1) is given a 0-33 km sounding at 300 m (111 rows,
standard-day density, a linear wind shear) as its atmosphere, and fitted
twice in this process, the NLP built from scratch each time:

* ``whole``: the sounding as read (every row a branch in each density and
  wind evaluation of the model; the earlier path);
* ``cut``: as `load_test` now gives it, the rows that span the measured
  altitudes plus `ATMOSPHERE_MARGIN_M` (`TableAtmosphere.within`).

Printed: rows, build time (code generation and compilation included, with a
fresh compile cache so that neither reuses the other's), solve time,
iterations and chi-square, and the ratios cut/whole.

    python benchmarks/atmosphere_table_cost.py
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.atmosphere import StandardAtmosphere, TableAtmosphere, density_at
from cpas_ocp.estimation import Estimator
from cpas_ocp.flight_test import FlightTest, load_test
from cpas_ocp.problems import load_problem
from cpas_ocp.simulate import simulate_problem


def sounding(folder: Path) -> TableAtmosphere:
    """Write sounding.csv into `folder`, point its manifest at it, and return it whole."""
    h = np.arange(0.0, 33_000.0 + 1.0, 300.0)
    d = pd.DataFrame({"altitude": h, "density": density_at(StandardAtmosphere(), h),
                      "wind_east": 5.0 + 1e-3 * h, "wind_north": -2.0 + 5e-4 * h})
    d.to_csv(folder / "sounding.csv", index=False)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["atmosphere"] = {"model": "table", "file": "sounding.csv", "columns": {
        "altitude": "m", "density": "kg/m^3", "wind_east": "m/s", "wind_north": "m/s"}}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return TableAtmosphere(h, d["density"].to_numpy(), d["wind_east"].to_numpy(),
                           d["wind_north"].to_numpy())


def fit(test: FlightTest, cache: Path) -> tuple[float, float, int, float]:
    """(build s, solve s, iterations, chi-square) with a compile cache of its own."""
    os.environ["CPAS_OCP_CACHE"] = str(cache)
    t0 = time.perf_counter()
    est = Estimator(test)
    build = time.perf_counter() - t0
    result = est.solve()
    return build, result.solver.wall_s, result.solver.iterations, result.chi_square


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "drogue"
        simulate_problem(load_problem("drogue"), folder, 1)
        whole = sounding(folder)
        cut = load_test(folder)
        runs = {"whole": dataclasses.replace(cut, atmosphere=whole), "cut": cut}
        print(f"{'table':6s} {'rows':>5s} {'build s':>8s} {'solve s':>8s} {'iter':>5s} "
              f"{'chi-square':>11s}")
        out = {}
        for label, test in runs.items():
            cache = Path(tmp) / f"cache-{label}"
            out[label] = fit(test, cache)
            shutil.rmtree(cache, ignore_errors=True)
            b, s, it, chi2 = out[label]
            print(f"{label:6s} {len(test.atmosphere.altitude_m):5d} {b:8.1f} {s:8.1f} {it:5d} "
                  f"{chi2:11.3f}", flush=True)
        (bw, sw, _, cw), (bc, sc, _, cc) = out["whole"], out["cut"]
        print(f"cut/whole: build {bc / bw:.2f}, solve {sc / sw:.2f}, "
              f"chi-square difference {cc - cw:+.4f}")


if __name__ == "__main__":
    main()
