"""Benchmark: calibration of the reported 95 % intervals on the built-in `drogue` problem.

Each seed simulates the `drogue` test (sensor and event-time noise drawn from
the seed) into a temporary folder and reconstructs it as a user would:
``Estimator(load_test(folder))``, ``solve()``, ``covariance(fit)``.  The
simulator's truth.json is moved out of the folder before the estimator loads
it and is read only afterwards, for scoring.  Per seed and free parameter:
estimate, one-sigma (Gauss-Newton KKT covariance), truth,
z = (estimate - truth) / sigma, and whether the 95 % interval
estimate +- 1.959964 sigma covers the truth (|z| < 1.959964).

If the covariance is right and the linearisation holds (estimate Gaussian
about the truth), then per parameter:
- the number of seeds covered is binomial(n, 0.95), since seeds are independent;
- z^2 is chi-square with 1 dof, so its mean over n seeds lies in
  chi2_n(0.025..0.975) / n.
Jointly, each seed's squared Mahalanobis distance of estimate from truth is
chi-square on the covariance's rank, and their sum over seeds is chi-square on
the summed dof.  The intervals of one seed are correlated, so the pooled
coverage is not binomial.  Its expected spread is computed from the reported
correlations (seeded Gaussian draws per seed).

Printed:
- the per-parameter table: coverage %, n, mean z, mean z^2;
- the summary: pooled coverage, parameters outside 90-98 % and outside the
  binomial range, and the Mahalanobis sum against chi-square;
- the failures and the wall time per seed.

    python benchmarks/drogue_coverage.py [--seeds 100] [--first 1] [--workers 2] [--out CSV]

One seed takes about 20 s on one core (simulate, build, solve, covariance).
If the compiled-function cache is cold, the first seeds also compile.
"""

from __future__ import annotations

import csv
import json
import sys
import tempfile
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import harness
import numpy as np
from scipy.stats import binom, chi2

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

Z95 = 1.959964  # two-sided 95 % normal quantile
NOMINAL = 0.95
NULL_DRAWS = 4000  # Gaussian draws per seed for the spread of its covered count


@dataclass
class SeedResult:
    """One seed's scores; `error` is set (and the rest empty) when the fit failed."""

    seed: int
    wall_s: float
    rows: list[dict] = field(default_factory=list)
    mahalanobis2: float = float("nan")
    dof: int = 0
    # Variance of the seed's number of covered intervals if the estimate were
    # Gaussian with the reported covariance (its intervals are correlated).
    null_count_variance: float = float("nan")
    error: str = ""


def score_seed(seed: int) -> SeedResult:
    """Simulate, reconstruct and score one seed of `drogue`."""
    timer = harness.Timer()
    with tempfile.TemporaryDirectory(prefix="cpas-coverage-") as tmp:
        folder = Path(tmp) / "test"
        simulate_problem(load_problem("drogue"), folder, seed)
        truth_file = (folder / "truth.json").rename(Path(tmp) / "truth.json")
        est = Estimator(load_test(folder))
        try:
            fit = est.solve()
        except SolverFailure as err:
            return SeedResult(seed, timer.elapsed(), error=f"solve: {err}")
        try:
            cov = est.covariance(fit)
        except (ValueError, np.linalg.LinAlgError) as err:  # e.g. a singular KKT system
            return SeedResult(seed, timer.elapsed(), error=f"covariance: {err}")
        truth = json.loads(truth_file.read_text())["parameters"]
    std = cov.std
    rows, scored = [], []
    for name in fit.free:
        est_v, true_v, s = fit.parameters[name], truth[name], std.get(name, 0.0)
        unscored = name in cov.at_bound or not s > 0.0  # on a bound, or no sigma reported
        z = float("nan") if unscored else (est_v - true_v) / s
        rows.append({"seed": seed, "parameter": name, "estimate": est_v, "std": s,
                     "truth": true_v, "z": z, "covered": "" if unscored else int(abs(z) < Z95),
                     "unscored": int(unscored)})
        if not unscored:
            scored.append(name)
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    null_var = null_count_variance(cov, scored, np.random.default_rng(seed))
    return SeedResult(seed, timer.elapsed(), rows, m2, dof, null_var)


def null_count_variance(cov: Covariance, names: list[str], rng: np.random.Generator) -> float:
    """Variance of the number of |z| < 1.96 among `names` when z ~ N(0, reported correlation).

    Binomial for independent intervals would be n * 0.95 * 0.05; correlated
    parameters (a start time and its stage's shape, the drag and load-cell
    scales) cover or miss together, which raises it.
    """
    idx = [cov.names.index(n) for n in names]
    w, v = np.linalg.eigh(cov.correlation()[np.ix_(idx, idx)])
    z = rng.standard_normal((NULL_DRAWS, len(idx))) @ (v * np.sqrt(np.clip(w, 0.0, None))).T
    return float(np.var(np.sum(np.abs(z) < Z95, axis=1)))


def run(seeds: list[int], workers: int) -> list[SeedResult]:
    """Score the seeds in parallel, with a progress line on stderr."""
    results: list[SeedResult] = []
    end = "\r" if sys.stderr.isatty() else "\n"
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(score_seed, s) for s in seeds]
        for future in as_completed(futures):
            results.append(future.result())
            failed = sum(1 for r in results if r.error)
            print(f"seeds done {len(results)}/{len(seeds)}, failures {failed}", end=end,
                  file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return sorted(results, key=lambda r: r.seed)


def report(results: list[SeedResult], elapsed_s: float) -> dict:
    """Print the coverage table, the summary, the failures and the timing; return the
    figures printed."""
    out: dict = {}
    ok = [r for r in results if not r.error]
    z_by_name: dict[str, list[float]] = defaultdict(list)
    unscored = 0
    for r in ok:
        for row in r.rows:
            if row["unscored"]:
                unscored += 1
            else:
                z_by_name[row["parameter"]].append(row["z"])
    if not z_by_name:
        print("no seed was reconstructed")
    else:
        print(f"{'parameter':34s} {'coverage %':>10s} {'n':>4s} {'mean z':>7s} {'mean z^2':>8s}")
        cover, per_parameter = {}, {}
        for name, zs in z_by_name.items():
            z = np.array(zs)
            cover[name] = float(np.mean(np.abs(z) < Z95))
            per_parameter[name] = {"coverage_percent": 100 * cover[name], "n": z.size,
                                   "mean_z": z.mean(), "mean_z2": np.mean(z**2)}
            print(f"{name:34s} {100 * cover[name]:10.1f} {z.size:4d} {z.mean():7.2f} "
                  f"{np.mean(z**2):8.2f}")
        out = summarise(z_by_name, cover, ok, unscored)
        out["per_parameter"] = per_parameter
    failures = [r for r in results if r.error]
    print(f"\nfailures: {len(failures)} of {len(results)} seeds")
    for r in failures:
        print(f"  seed {r.seed}: {r.error}")
    wall = np.array([r.wall_s for r in results])
    print(f"wall time per seed (simulate, build, solve, covariance): mean {wall.mean():.1f} s, "
          f"median {np.median(wall):.1f} s, max {wall.max():.1f} s; "
          f"study {elapsed_s / 60:.1f} min")
    return {**out, "seeds": len(results), "failures": {r.seed: r.error for r in failures},
            "wall_s_per_seed": {"mean": wall.mean(), "median": np.median(wall),
                                "max": wall.max()}, "study_s": elapsed_s}


def summarise(z_by_name: dict[str, list[float]], cover: dict[str, float],
              ok: list[SeedResult], unscored: int) -> dict:
    """Coverage against the binomial, mean z^2 against chi-square, Mahalanobis sum; return
    the headline figures."""
    n = max(len(z) for z in z_by_name.values())
    lo, hi = binom.interval(0.95, n, NOMINAL)
    z2_lo, z2_hi = chi2.interval(0.95, n)
    all_z = np.concatenate([np.array(z) for z in z_by_name.values()])
    pooled = float(np.mean(np.abs(all_z) < Z95))
    # Chance that one parameter's coverage falls below 90 % or above 98 % at nominal.
    p_out = binom.cdf(np.ceil(0.90 * n) - 1, n, NOMINAL) + binom.sf(np.floor(0.98 * n), n, NOMINAL)
    outside = [k for k, c in cover.items() if not 0.90 <= c <= 0.98]
    outside_binom = [k for k, c in cover.items() if not lo <= c * n <= hi]
    z2 = {k: float(np.mean(np.square(z))) for k, z in z_by_name.items()}
    z2_out = [k for k, v in z2.items() if not z2_lo / n <= v <= z2_hi / n]
    null_sd = np.sqrt(sum(r.null_count_variance for r in ok)) / all_z.size
    m2 = sum(r.mahalanobis2 for r in ok)
    dof = sum(r.dof for r in ok)
    above = sum(r.mahalanobis2 > chi2.ppf(0.95, r.dof) for r in ok)
    print(f"\n{len(ok)} seeds reconstructed, {len(cover)} parameters, {all_z.size} intervals"
          + (f" ({unscored} estimates on a bound or without sigma, not scored)"
             if unscored else ""))
    print(f"per-parameter coverage: min {100 * min(cover.values()):.1f} %, "
          f"max {100 * max(cover.values()):.1f} %")
    print(f"binomial 95 % range of one parameter's coverage over n = {n} seeds at 95 %: "
          f"{100 * lo / n:.0f}-{100 * hi / n:.0f} %; outside it: {len(outside_binom)} "
          f"(expected about {0.05 * len(cover):.1f}) {', '.join(outside_binom)}")
    print(f"outside 90-98 %: {len(outside)} (expected {p_out * len(cover):.1f} at nominal) "
          f"{', '.join(outside)}")
    print(f"pooled coverage: {100 * pooled:.2f} % (at nominal 95 % +- {100 * 1.96 * null_sd:.2f} "
          f"given the reported correlations; +- "
          f"{100 * 1.96 * np.sqrt(NOMINAL * (1 - NOMINAL) / all_z.size):.2f} if independent)")
    print(f"mean z^2: min {min(z2.values()):.2f}, max {max(z2.values()):.2f}, over all "
          f"{np.mean(all_z**2):.2f}; chi-square 95 % range of one parameter's "
          f"{z2_lo / n:.2f}-{z2_hi / n:.2f}; outside it: {len(z2_out)} {', '.join(z2_out)}")
    print(f"Mahalanobis^2 summed over seeds: {m2:.1f} on {dof} dof (ratio {m2 / dof:.3f}), "
          f"P(chi2_{dof} > sum) = {chi2.sf(m2, dof):.3g}; seeds above their chi-square 95 % "
          f"quantile: {above} of {len(ok)} (expected {0.05 * len(ok):.1f})")
    return {"reconstructed": len(ok), "intervals": int(all_z.size), "unscored": unscored,
            "pooled_coverage": pooled, "outside_90_98": outside,
            "outside_binomial": outside_binom, "outside_z2_range": z2_out,
            "mahalanobis2": m2, "dof": dof, "mahalanobis2_p": chi2.sf(m2, dof),
            "seeds_above_chi2_95": int(above)}


def write_csv(results: list[SeedResult], path: Path) -> None:
    fields = ["seed", "parameter", "estimate", "std", "truth", "z", "covered", "unscored",
              "error"]
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, restval="")
        writer.writeheader()
        for r in results:
            writer.writerows(r.rows if not r.error else [{"seed": r.seed, "error": r.error}])


def main() -> None:
    ap = harness.parser(__doc__, seed=None, seed_help="recorded only: each seed's draws are "
                        "seeded by that seed (--first, --seeds)")
    ap.add_argument("--seeds", type=int, default=100, help="number of seeds (default 100)")
    ap.add_argument("--first", type=int, default=1, help="first seed (default 1)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", type=Path, default=None, help="CSV of every seed and parameter")
    args = ap.parse_args()
    timer = harness.Timer()
    results = run(list(range(args.first, args.first + args.seeds)), args.workers)
    if args.out:
        write_csv(results, args.out)
    figures = report(results, timer.elapsed())
    harness.report("drogue_coverage", first=args.first, **figures)


if __name__ == "__main__":
    main()
