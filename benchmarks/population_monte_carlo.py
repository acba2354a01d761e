"""Benchmark: Monte Carlo cases from a campaign's population against its point estimates.

From one campaign folder (`cpas-ocp campaign`; `benchmarks/population_coverage.py
--keep DIR` leaves one per seed and scenario), draws 200,000 cases per canopy type and
stage twice (`co.dispersions`): from the point estimates' dispersions, and from the
fitted population (`--population`), both within the same caps and grown hull. Prints
each parameter's spread (the standard deviation of the log of the cases) both ways,
the population's tau and the truth's where given, then flies the first `--fly` cases
of each through one test's fit (`peak_load_study.run_monte_carlo`, as `cpas-ocp
montecarlo` does) and prints the peak-tension quantiles both ways with their ratio.

    python benchmarks/population_monte_carlo.py CAMPAIGN TEST_DIR [--cases 200000]
        [--fly 20000] [--seed 1] [--workers 2]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
import numpy as np
import pandas as pd

from cpas_ocp.api import dispersions, fit_estimator
from cpas_ocp.campaign.peak_load_study import match_cases, run_monte_carlo
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test


def spreads(folder: Path) -> pd.DataFrame:
    """Per cases file and parameter, the standard deviation of the log of the cases."""
    rows = []
    for path in sorted(folder.glob("cases_*.parquet")):
        cases = pd.read_parquet(path)
        for name in cases.columns:
            rows.append({"cases": path.stem.removeprefix("cases_"), "parameter": name,
                         "sd_log": float(np.log(cases[name]).std())})
    return pd.DataFrame(rows)


def main() -> None:
    ap = harness.parser(__doc__, seed=1, seed_help="seed of the cases' draws")
    ap.add_argument("campaign", type=Path)
    ap.add_argument("test_dir", type=Path)
    ap.add_argument("--cases", type=int, default=200_000)
    ap.add_argument("--fly", type=int, default=20_000)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    timer = harness.Timer()
    with tempfile.TemporaryDirectory() as tmp:
        folders = {}
        for label, from_population in (("point estimates", False), ("population", True)):
            with timer(f"draw {label}"):
                done = dispersions(args.campaign, Path(tmp) / label.replace(" ", "_"),
                                   args.cases, args.seed, from_population)
            folders[label] = done.out
            print(f"{label}: {args.cases:,} cases per type and stage in "
                  f"{timer[f'draw {label}']:.1f} s")
        table = spreads(folders["point estimates"]).merge(
            spreads(folders["population"]), on=["cases", "parameter"],
            suffixes=("_point", "_population"))
        table["ratio"] = table.sd_log_population / table.sd_log_point
        print("\nspread of the cases (sd of log):")
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
        test = load_test(args.test_dir)
        rec = fit_estimator(Estimator(test))
        quantiles = {}
        for label, folder in folders.items():
            stages = match_cases(test, folder, args.fly)
            with timer(f"fly {label}"):
                for result in run_monte_carlo(rec.fit, stages, args.workers):
                    q = result.quantiles()
                    quantiles[(result.cases.label, label)] = q.set_index(
                        "quantile").peak_tension_lbf
            print(f"{label}: flown in {timer[f'fly {label}']:.0f} s")
    print(f"\npeak tension (lbf), the first {args.fly:,} cases of each:")
    peaks = []
    for stage in sorted({s for s, _ in quantiles}):
        point, pop = quantiles[(stage, "point estimates")], quantiles[(stage, "population")]
        print(f"{stage}: {'quantile':>8s} {'point':>10s} {'population':>10s} {'ratio':>6s}")
        for q in point.index:
            peaks.append({"stage": stage, "quantile": q, "point": point[q], "population": pop[q],
                          "ratio": harness.ratio(pop[q], point[q])})
            print(f"{'':{len(stage)}s}  {q:8.3f} {point[q]:10,.0f} {pop[q]:10,.0f} "
                  f"{peaks[-1]['ratio']:6.3f}")
    harness.report("population_monte_carlo", cases=args.cases, fly=args.fly,
                   seconds=timer.seconds(), spread=table.to_dict("records"),
                   peak_tension_lbf=peaks)


if __name__ == "__main__":
    main()
