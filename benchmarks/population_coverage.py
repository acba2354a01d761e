"""Benchmark: a campaign's population recovered from reconstructed tests, over many seeds.

Each seed draws a simulated campaign from a known population and reconstructs
every test with the tool (`campaign.run_campaign`, as `cpas-ocp campaign`
does), then fits the population from the campaign's tables
(`population_study.population_groups`, as `cpas-ocp population` does) and
scores it against the truth, which the fits never see.

The campaign: 10 FBCP-like tests of canopy type `fbcp` and 10 of type
`drogue` (both the `fbcp` problem, two canopies per test: the paper pools FBCP
and Drogue first stages, Figure 16), each canopy's
(CdS, Ck, n_p, expopen, t_k) drawn from a lognormal population with median mu,
between-test standard deviations tau (in log space) and correlations R, and
one covariate: half the tests fly suspension lines of 14 ft, half 10.5 ft,
the longer lines adding `LINE_EFFECT` to log CdS.  Two scenarios share the
`fbcp` tests:
- `same`: `drogue` drawn from the same population;
- `differ`: `drogue`'s mean shifted by two between-test standard deviations
  in every parameter.

Scored per seed:
- the coverage of the 95 % intervals of each type's population mean (the
  intercept, at the campaign's mean line length), of the line-length effect
  and of each tau (`differ`, each type fitted alone with line length as a
  covariate);
- the grouping test by type on the two types pooled: kept pooled in `same`,
  separated in `differ`;
- the point-estimate method: the standard deviation of the estimates over the
  openings against tau (its bias).

The scoring runs on `--workers` processes (each population fit on one thread).

    python benchmarks/population_coverage.py [--seeds 50] [--first 1] [--workers 2]
        [--keep DIR] [--analyse-only] [--diagonal]

With `--keep`, each seed's campaign folders and truth are kept there (a seed
already there is not reconstructed again) and `--analyse-only` rescores them
without reconstructing.  One seed simulates and reconstructs 30 tests; the
seeds are reconstructed four at a time in one campaign.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import harness
import numpy as np
from scipy import stats

from cpas_ocp.campaign.campaign import run_campaign
from cpas_ocp.campaign.dispersion_study import read_parameter_table
from cpas_ocp.campaign.population_study import population_groups, read_covariance_table
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import Problem, load_problem
from cpas_ocp.reports.study_reports import write_campaign

NAMES = ("CdS", "Ck", "n_p", "expopen", "t_k")
MEDIAN = np.array([2.0, 1.55, 9.5, 1.7, 0.135])  # SI (CdS in m^2, t_k in s)
TAU = np.array([0.05, 0.03, 0.06, 0.08, 0.08])  # log space
CORRELATION = np.array([[1.0, 0.0, 0.0, 0.0, 0.0],
                        [0.0, 1.0, -0.5, 0.3, 0.0],
                        [0.0, -0.5, 1.0, 0.0, 0.3],
                        [0.0, 0.3, 0.0, 1.0, 0.0],
                        [0.0, 0.0, 0.3, 0.0, 1.0]])
LINES_FT = (10.5, 14.0)
FT = 0.3048
LINE_EFFECT = 0.08  # log CdS, 14 ft lines against 10.5 ft
TESTS_PER_TYPE = 10
TYPES = ("fbcp", "drogue")
BATCH = 4  # seeds reconstructed in one campaign


def draw_truth(seed: int) -> dict[str, list[dict]]:
    """Per scenario, each test's type, line length (ft) and two canopies' parameters (SI)."""
    rng = np.random.default_rng(seed)
    omega = CORRELATION * np.outer(TAU, TAU)
    per_m = LINE_EFFECT / ((LINES_FT[1] - LINES_FT[0]) * FT)
    tests: dict[str, list[dict]] = {"same": [], "differ": []}
    for kind in TYPES:
        eta = rng.multivariate_normal(np.zeros(len(NAMES)), omega, (TESTS_PER_TYPE, 2))
        for i in range(TESTS_PER_TYPE):
            line_ft = LINES_FT[i % 2]
            for scenario in ("same", "differ"):
                shift = 2.0 * TAU if (scenario == "differ" and kind == "drogue") else 0.0
                log_theta = np.log(MEDIAN) + shift + eta[i]
                log_theta[:, 0] += per_m * (line_ft - LINES_FT[0]) * FT
                tests[scenario].append({"type": kind, "line_ft": line_ft, "canopies": [
                    dict(zip(NAMES, np.exp(lt).tolist(), strict=True)) for lt in log_theta]})
    return tests


def variant(base: Problem, test: dict) -> Problem:
    """The `fbcp` problem with this test's canopy type, line length and parameters."""
    manifest = json.loads(json.dumps(base.manifest))
    truth = dict(base.truth)
    for chute, values in zip(manifest["parachutes"], test["canopies"], strict=True):
        chute["type"] = test["type"]
        chute["line_length"] = {"value": test["line_ft"], "unit": "ft"}
        for name, value in values.items():
            truth[f"{name}[{chute['name']},stage1]"] = value
    return dataclasses.replace(base, manifest=manifest, truth=truth)


def simulate_seed(seed: int, root: Path) -> dict[str, list[Path]]:
    """Simulate `seed`'s tests into root/seed<N>/; per scenario, its test folders (the
    `fbcp` tests shared by both)."""
    base = load_problem("fbcp")
    folders: dict[str, list[Path]] = {}
    shared: dict[int, Path] = {}
    for scenario, tests in draw_truth(seed).items():
        folders[scenario] = []
        for i, test in enumerate(tests):
            if scenario == "differ" and test["type"] == "fbcp":
                folders[scenario].append(shared[i])
                continue
            folder = root / f"seed{seed}" / scenario / f"t{i:02d}"
            simulate_problem(variant(base, test), folder, 1000 * seed + i)
            (folder / "truth.json").unlink()
            folders[scenario].append(folder)
            shared[i] = folder
    return folders


def reconstruct_seeds(seeds: list[int], keep: Path, workers: int) -> None:
    """Simulate the seeds' tests and reconstruct them all in one campaign (one pool of
    workers), then write each seed's scenarios as campaign folders keep/seed<N>/<scenario>
    with the seed's truth."""
    seeds = [s for s in seeds if not (keep / f"seed{s}" / "truth.json").is_file()]
    if not seeds:
        return
    with tempfile.TemporaryDirectory() as tmp:
        plan = {s: simulate_seed(s, Path(tmp)) for s in seeds}
        every = sorted({str(f) for p in plan.values() for fs in p.values() for f in fs})
        outcomes = {o.folder: o for o in run_campaign(every, workers=workers)}
        for seed, scenarios in plan.items():
            for scenario, folders in scenarios.items():
                write_campaign([outcomes[str(f)] for f in folders],
                               keep / f"seed{seed}" / scenario)
            (keep / f"seed{seed}" / "truth.json").write_text(json.dumps(draw_truth(seed)))


def score_seed(seed: int, folder: Path, full_omega: bool) -> dict:
    """The seed's intervals and tests against the population's truth (the module's
    constants; the kept folder's draws checked to be this script's)."""
    if json.loads((folder / "truth.json").read_text()) != json.loads(json.dumps(
            draw_truth(seed))):
        raise SystemExit(f"{folder}: drawn by another version of this script")
    per_m = LINE_EFFECT / ((LINES_FT[1] - LINES_FT[0]) * FT)
    out: dict = {"mu": [], "effect": [], "tau": [], "spread": [], "tau_hat": []}
    table = read_parameter_table(folder / "differ")
    cov = read_covariance_table(folder / "differ")
    groups, _ = population_groups(table, cov, str(folder), covariates=("line_length",),
                                  full_omega=full_omega)
    for group in groups:
        kind = group.members[0][0]
        shift = 2.0 * TAU if kind == "drogue" else np.zeros(len(NAMES))
        mean_line = float(group.covariates.line_length.mean())
        fit = group.fit
        for j, name in enumerate(fit.data.names):
            k = NAMES.index(name)
            mu = np.log(MEDIAN[k]) + shift[k]
            if name == "CdS":
                mu += per_m * (mean_line - LINES_FT[0] * FT)
            column = next(c for c in fit.data.columns if c.startswith("line_length"))
            out["mu"].append((kind, name, fit.coefficients[(name, "intercept")].covers(mu)))
            out["effect"].append((kind, name, fit.coefficients[(name, column)].covers(
                per_m if name == "CdS" else 0.0)))
            out["tau"].append((kind, name, fit.tau[name].covers(TAU[k])))
            out["tau_hat"].append((kind, name, fit.tau[name].value))
            out["spread"].append((kind, name, float(group.point_spread[j])))
    for scenario in ("same", "differ"):
        table = read_parameter_table(folder / scenario)
        cov = read_covariance_table(folder / scenario)
        pooled, _ = population_groups(table, cov, str(folder), full_omega=full_omega,
                                      pool=[[(t, "stage1") for t in TYPES]])
        test = next(g for g in pooled[0].groupings if g.covariate == "type")
        out[f"separate_{scenario}"] = test.separate
        out[f"p_{scenario}"] = test.p_value
    return out


def summarise(scores: list[dict]) -> dict:
    """Print the coverage table, the grouping rates and the point-estimate bias; return
    them."""
    n = len(scores)
    table, separated = [], {}
    lo, hi = stats.binom.ppf([0.025, 0.975], n, 0.95) / n
    print(f"\n{n} seeds; a 95 % interval covers in {100 * lo:.0f}-{100 * hi:.0f} % of them "
          "if it is right (binomial 95 % range)\n")
    print(f"{'type':8s} {'parameter':10s} {'mu':>6s} {'effect':>7s} {'tau':>6s}  "
          f"{'tau true':>8s} {'mean tau^':>9s} {'mean point SD':>13s}")
    for kind in TYPES:
        for name in NAMES:
            def rate(key: str, kind: str = kind, name: str = name) -> float:
                hits = [c for s in scores for (t, p, c) in s[key] if t == kind and p == name]
                return 100.0 * np.mean(hits) if hits else np.nan

            def mean(key: str, kind: str = kind, name: str = name) -> float:
                v = [c for s in scores for (t, p, c) in s[key] if t == kind and p == name]
                return float(np.mean(v)) if v else np.nan
            k = NAMES.index(name)
            print(f"{kind:8s} {name:10s} {rate('mu'):6.0f} {rate('effect'):7.0f} "
                  f"{rate('tau'):6.0f}  {TAU[k]:8.3f} {mean('tau_hat'):9.4f} "
                  f"{mean('spread'):13.4f}")
            table.append({"type": kind, "parameter": name, "mu_cover_percent": rate("mu"),
                          "effect_cover_percent": rate("effect"),
                          "tau_cover_percent": rate("tau"), "tau_true": TAU[k],
                          "mean_tau_hat": mean("tau_hat"), "mean_point_sd": mean("spread")})
    for scenario in ("same", "differ"):
        rate = 100.0 * np.mean([s[f"separate_{scenario}"] for s in scores])
        print(f"grouping by type, {scenario}: separated in {rate:.0f} % of seeds")
        separated[scenario] = rate
    return {"seeds_scored": n, "binomial_95_percent": [100 * lo, 100 * hi],
            "coverage": table, "separated_percent": separated}


def main() -> None:
    ap = harness.parser(__doc__, seed=None, seed_help="recorded only: each seed's draws are "
                        "seeded by that seed (--first, --seeds)")
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, default=None)
    ap.add_argument("--analyse-only", action="store_true")
    ap.add_argument("--diagonal", action="store_true", help="a diagonal Omega")
    args = ap.parse_args()
    keep = args.keep or Path(tempfile.mkdtemp(prefix="population-"))
    timer = harness.Timer()
    seeds = list(range(args.first, args.first + args.seeds))
    if not args.analyse_only:
        for b in range(0, len(seeds), BATCH):
            reconstruct_seeds(seeds[b:b + BATCH], keep, args.workers)
            print(f"seeds {seeds[b]}-{seeds[min(b + BATCH, len(seeds)) - 1]} reconstructed, "
                  f"{timer.elapsed():.0f} s so far", file=sys.stderr, flush=True)
    done = [s for s in seeds if (keep / f"seed{s}" / "truth.json").is_file()]
    failed = sum(len(read_failures(keep / f"seed{s}" / c)) for s in done
                 for c in ("same", "differ"))
    with ProcessPoolExecutor(args.workers) as pool:
        scores = list(pool.map(score_seed, done, [keep / f"seed{s}" for s in done],
                               [not args.diagonal] * len(done)))
    figures = summarise(scores)
    print(f"reconstructions that were not a result: {failed}")
    if args.keep is None:
        shutil.rmtree(keep)
    harness.report("population_coverage", first=args.first, diagonal=args.diagonal,
                   not_a_result=failed, **figures)


def read_failures(folder: Path) -> list[str]:
    path = folder / "failures.csv"
    return path.read_text().splitlines()[1:] if path.is_file() else []


if __name__ == "__main__":
    main()
