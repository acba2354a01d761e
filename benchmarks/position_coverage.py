"""Benchmark: canopy positions that differ by fixed amounts, no between-test spread, through
reconstructed tests.

Every test of a campaign is the `drogue` problem with its own truth: two Drogues whose
parameters differ by fixed amounts (drogue2's t_k 17 % longer than drogue1's in the first
stage, 22 % shorter in the second; Ck 5 % lower, ...), the same in every test, so the
truth has no test-to-test spread at all.  Each seed simulates `--tests` tests with its
own sensor noise, reconstructs them as `cpas-ocp campaign` does, and fits each stage's
population as `cpas-ocp population` does, with the position as a covariate (the default)
and without (`--no-position`).  The fits never see the truth.

Scored per stage and parameter over the seeds:
- with the position: the 95 % intervals of the median (drogue1's) and of the position's
  effect (log drogue2 - log drogue1) covering the truth, and tau's covering 0;
- without it: the mean of tau^, which the position difference inflates (about half the
  difference in log), and how often its interval covers 0;
- where the campaign kept the covariances between a test's canopies, the test-level and
  canopy-level taus (`nested_population`) covering 0.

    python benchmarks/position_coverage.py [--seeds 10] [--tests 6] [--workers 2]
        [--keep DIR]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
import numpy as np
from scipy import stats

from cpas_ocp.campaign.campaign import run_campaign
from cpas_ocp.campaign.dispersion_study import read_parameter_table
from cpas_ocp.campaign.population_study import population_groups, read_covariance_table
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem
from cpas_ocp.reports.study_reports import write_campaign


def campaign(seed: int, tests: int, keep: Path, workers: int) -> Path:
    """The seed's campaign folder under `keep` (simulated and reconstructed unless there)."""
    folder = keep / f"seed{seed}"
    if (folder / "parameters.csv").is_file():
        return folder
    problem = load_problem("drogue")
    with tempfile.TemporaryDirectory() as tmp:
        folders = []
        for i in range(tests):
            out = Path(tmp) / f"t{i:02d}"
            simulate_problem(problem, out, 10_000 * seed + i)
            (out / "truth.json").unlink()
            folders.append(str(out))
        write_campaign(run_campaign(folders, workers=workers, progress=True), folder)
    return folder


def score(folder: Path) -> list[dict]:
    """A row per stage and parameter of the seed's populations against the truth."""
    truth = load_problem("drogue").truth
    table = read_parameter_table(folder)
    cov = read_covariance_table(folder)
    with_position, _ = population_groups(table, cov, str(folder))
    without, _ = population_groups(table, cov, str(folder), by_position=False)
    rows = []
    for group, plain in zip(with_position, without, strict=True):
        stage = group.members[0][1]
        fit = group.fit
        column = next((c for c in fit.data.columns if c.startswith("position=")), None)
        for name in fit.data.names:
            first = np.log(truth[f"{name}[drogue1,{stage}]"])
            second = np.log(truth[f"{name}[drogue2,{stage}]"])
            nested = group.nested
            rows.append({
                "stage": stage, "parameter": name, "position_taken": column is not None,
                "mu": fit.coefficients[(name, "intercept")].covers(first),
                "effect": column is not None
                and fit.coefficients[(name, column)].covers(second - first),
                "tau_zero": fit.tau[name].lower == 0.0,
                "tau_without": plain.fit.tau[name].value,
                "tau_without_zero": plain.fit.tau[name].lower == 0.0,
                "difference": abs(second - first),
                "nested_zero": None if nested is None
                else nested.tau_test[name].lower == 0.0
                and nested.tau_canopy[name].lower == 0.0})
    return rows


def main() -> None:
    ap = harness.parser(__doc__, seed=None, seed_help="not used: the seeds are 1..--seeds")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--tests", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, default=None)
    args = ap.parse_args()
    timer = harness.Timer()
    with tempfile.TemporaryDirectory() as tmp:
        keep = args.keep or Path(tmp)
        rows = []
        for seed in range(1, args.seeds + 1):
            with timer("campaign"):
                folder = campaign(seed, args.tests, keep, args.workers)
            rows += [r | {"seed": seed} for r in score(folder)]
            print(f"seed {seed}: campaign {timer['campaign']:.0f} s", flush=True)
    n = args.seeds
    lo, hi = stats.binom.ppf([0.025, 0.975], n, 0.95) / n
    print(f"\n{n} campaigns of {args.tests} tests; a right 95 % interval covers in "
          f"{100 * lo:.0f}-{100 * hi:.0f} % of them (binomial 95 % range)\n")
    print(f"{'stage':7s} {'parameter':9s} {'|d2-d1|':>8s} {'mu':>5s} {'effect':>6s} "
          f"{'tau~0':>6s} {'nested~0':>8s} {'tau^ without':>12s} {'~0 without':>10s}")
    summary = []
    keys = sorted({(r["stage"], r["parameter"]) for r in rows})
    for stage, name in keys:
        part = [r for r in rows if r["stage"] == stage and r["parameter"] == name]
        nested = [r["nested_zero"] for r in part if r["nested_zero"] is not None]
        line = {"stage": stage, "parameter": name, "difference": part[0]["difference"],
                "mu": np.mean([r["mu"] for r in part]),
                "effect": np.mean([r["effect"] for r in part]),
                "tau_zero": np.mean([r["tau_zero"] for r in part]),
                "nested_zero": np.mean(nested) if nested else None,
                "tau_without": np.mean([r["tau_without"] for r in part]),
                "tau_without_zero": np.mean([r["tau_without_zero"] for r in part])}
        summary.append(line)
        nested_text = "-" if line["nested_zero"] is None else f"{line['nested_zero']:.2f}"
        print(f"{stage:7s} {name:9s} {line['difference']:8.3f} {line['mu']:5.2f} "
              f"{line['effect']:6.2f} {line['tau_zero']:6.2f} {nested_text:>8s} "
              f"{line['tau_without']:12.3f} {line['tau_without_zero']:10.2f}")
    harness.report("position_coverage", seeds=n, tests=args.tests, summary=summary,
                   campaign_s=timer.laps.get("campaign", []))


if __name__ == "__main__":
    main()
