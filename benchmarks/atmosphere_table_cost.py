"""Benchmark: the cost of a fit against the length of its day-of-flight sounding.

The `drogue` problem (seed 1 unless `--seed`) is given a 0-33 km sounding (standard-day
density, and wind columns of zeros, so that the tables describe the air the
flight was simulated in) at 3 km, 300 m and 75 m (12, 111 and 441 rows) as
its atmosphere, and fitted once per table in this process, the
NLP built from scratch each time with a fresh compile cache.  Printed: rows,
build time (code generation and compilation included), solve time,
iterations and chi-square, and the ratios of build time and time per
iteration against the 12-row table.

The table is a linear interpolant (a lookup) in the model.  When it was a
chain of branches, one per row, the 111-row table ran the compiler out of
memory (7.7 GB) and took 259 s to build and 435 s to solve in the virtual
machine, and tests were cut on loading to the rows they flew through.

    python benchmarks/atmosphere_table_cost.py [--seed 1]
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import harness
import numpy as np
import pandas as pd

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.atmosphere import StandardAtmosphere, density_at
from cpas_ocp.physics.flight_test import FlightTest


def sounding(folder: Path, step_m: float) -> None:
    """Write sounding.csv (0-33 km every `step_m`) into `folder` and point its manifest at it."""
    h = np.arange(0.0, 33_000.0 + 1.0, step_m)
    d = pd.DataFrame({"altitude": h, "density": density_at(StandardAtmosphere(), h),
                      "wind_east": 0.0 * h, "wind_north": 0.0 * h})
    d.to_csv(folder / "sounding.csv", index=False)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["atmosphere"] = {"model": "table", "file": "sounding.csv", "columns": {
        "altitude": "m", "density": "kg/m^3", "wind_east": "m/s", "wind_north": "m/s"}}
    (folder / "manifest.json").write_text(json.dumps(manifest))


def fit(test: FlightTest, cache: Path) -> tuple[float, float, int, float]:
    """(build s, solve s, iterations, chi-square) with a compile cache of its own."""
    os.environ["CPAS_OCP_CACHE"] = str(cache)
    timer = harness.Timer()
    with timer("build"):
        est = Estimator(test)
    result = est.solve()
    return timer["build"], result.solver.wall_s, result.solver.iterations, result.chi_square


def main() -> None:
    args = harness.parser(__doc__, seed=1).parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "drogue"
        simulate_problem(load_problem("drogue"), base, args.seed)
        print(f"{'rows':>5s} {'build s':>8s} {'solve s':>8s} {'iter':>5s} {'chi-square':>12s}"
              f" {'build ratio':>11s} {'s/it ratio':>10s}")
        first = None
        for step_m in (3_000.0, 300.0, 75.0):
            folder = Path(tmp) / f"drogue-{step_m:g}"
            shutil.copytree(base, folder)
            sounding(folder, step_m)
            test = load_test(folder)
            cache = Path(tmp) / f"cache-{step_m:g}"
            b, s, it, chi2 = fit(test, cache)
            shutil.rmtree(cache, ignore_errors=True)
            first = first or (b, s / it)
            rows.append({"rows": len(test.atmosphere.altitude_m), "build_s": b, "solve_s": s,
                         "iterations": it, "chi_square": chi2,
                         "build_ratio": harness.ratio(b, first[0]),
                         "per_iteration_ratio": harness.ratio(s / it, first[1])})
            print(f"{rows[-1]['rows']:5d} {b:8.1f} {s:8.1f} {it:5d} {chi2:12.3f} "
                  f"{rows[-1]['build_ratio']:11.2f} {rows[-1]['per_iteration_ratio']:10.2f}",
                  flush=True)
    harness.report("atmosphere_table_cost", tables=rows)


if __name__ == "__main__":
    main()
