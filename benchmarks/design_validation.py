"""Benchmark: the sigma `cpas-ocp design` predicts against the spread of estimates over seeds.

For a plan file (`docs/plans/drogue.json`, `docs/plans/fbcp.json`), the design is made
(`inference.flight_test_design.design`): each candidate's predicted covariance, and the
single changes ranked by the sigma they remove from the plan's parameters of interest.
Then the first candidate, the top-ranked change and the runner-up (or the changes named
with --changes) are each flown over seeds 1..N (from --first): the planned test
simulated with sensor and event-timing noise from the seed, its truth.json moved out of
the folder before the estimator loads it, and reconstructed as a user would
(``Estimator(load_test(folder))`` from the offline reduction, ``solve()``).  The truth
is read only to check the estimates' mean.

Printed per instrumentation and free parameter: the predicted sigma, the empirical
standard deviation of the estimates over the seeds (ddof 1), their ratio, and whether
the ratio lies in the band the seeds' number allows if the prediction is right: the
sample standard deviation of N Gaussian draws lies within
sqrt(chi2_{N-1}(0.025..0.975) / (N-1)) of the true one (0.80-1.20 for N = 50), so some
of 41 parameters fall outside +-15 % by chance alone.  Then, per change, the mean
fraction of the interest parameters' sigma it removes: predicted, and empirical with
its bootstrap 95 % interval over the seeds (seeded by `--seed`); the change ranked first is
confirmed when its empirical reduction is the largest.

    python benchmarks/design_validation.py docs/plans/drogue.json --seeds 50 --workers 2 \
        [--first 1] [--changes "LABEL" ...] [--out CSV] [--seed 20261126]

One `drogue` seed takes about 10-20 s on one core, one `fbcp` seed about 1 s.
"""

from __future__ import annotations

import csv
import json
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import harness
import numpy as np
from scipy.stats import chi2

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference.flight_test_design import Prediction, TestDesign, design, simulate_planned
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.flight_test_plan import Instrumentation, load_plan
from cpas_ocp.io.problems import Problem

BOOTSTRAP = 2000  # resamples of the seeds for the interval of an empirical reduction
BOOTSTRAP_SEED = 20261126  # the default --seed


def fly(problem: Problem, instr: Instrumentation, seed: int) -> dict:
    """One seed of `instr`: the estimates (SI) by name, or the solver's failure."""
    with tempfile.TemporaryDirectory(prefix="cpas-design-") as tmp:
        folder = Path(tmp) / "test"
        simulate_planned(problem, instr, folder, seed)
        (folder / "truth.json").rename(Path(tmp) / "truth.json")  # out of the estimator's reach
        est = Estimator(load_test(folder))
        try:
            fit = est.solve()
        except SolverFailure as err:
            return {"seed": seed, "error": str(err)}
        truth = json.loads((Path(tmp) / "truth.json").read_text())["parameters"]
        return {"seed": seed, "estimates": {n: fit.parameters[n] for n in fit.free},
                "truth": {n: truth[n] for n in fit.free}}


def flown(problem: Problem, cases: list[Prediction], seeds: list[int], workers: int
          ) -> dict[str, list[dict]]:
    """Every case flown over `seeds` in parallel, by instrumentation name."""
    out: dict[str, list[dict]] = {c.instrumentation.name: [] for c in cases}
    end = "\r" if sys.stderr.isatty() else "\n"
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(fly, problem, c.instrumentation, s): c.instrumentation.name
                   for c in cases for s in seeds}
        for k, future in enumerate(as_completed(futures), 1):
            out[futures[future]].append(future.result())
            print(f"fits done {k}/{len(futures)}", end=end, file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return {k: sorted(v, key=lambda r: r["seed"]) for k, v in out.items()}


def chosen_cases(found: TestDesign, labels: list[str]) -> list[Prediction]:
    """The first candidate, then the named changes, or the top two of the ranking."""
    ranked = [r for r in found.ranking if np.isfinite(r.score)]
    picked = ([next(r for r in ranked if r.change.label == lab) for lab in labels] if labels
              else ranked[:2])
    return [found.baseline] + [r.prediction for r in picked]


def table(case: Prediction, runs: list[dict], rows: list[dict]) -> tuple[np.ndarray, dict]:
    """Print predicted against empirical sigma of every free parameter; the estimates
    (seeds x parameters) of the converged seeds, and the counts the table ends with."""
    ok = [r for r in runs if "estimates" in r]
    names = case.covariance.names
    est = np.array([[r["estimates"][n] for n in names] for r in ok])
    n = len(ok)
    lo, hi = np.sqrt(chi2.ppf([0.025, 0.975], n - 1) / (n - 1))
    print(f"\n## {case.instrumentation.name}: {n} of {len(runs)} seeds converged; "
          f"band for empirical/predicted at N = {n}: {lo:.2f}-{hi:.2f}")
    print(f"{'parameter':28s} {'predicted':>11s} {'empirical':>11s} {'ratio':>6s} "
          f"{'bias/sd':>8s}  ")
    outside, ratios, within15 = [], [], 0
    truth = np.array([[r["truth"][nm] for nm in names] for r in ok])
    for j, name in enumerate(names):
        pred = case.sigma(name)
        emp = float(np.std(est[:, j], ddof=1))
        bias = float(np.mean(est[:, j] - truth[:, j]) / (emp / np.sqrt(n))) if emp else 0.0
        ratio = emp / pred if pred else float("nan")
        flag = "" if lo <= ratio <= hi else " outside band"
        outside += [f"{name} {ratio:.2f}"] if flag else []
        ratios.append(ratio)
        within15 += abs(ratio - 1.0) <= 0.15
        print(f"{name:28s} {pred or float('nan'):11.4g} {emp:11.4g} {ratio:6.2f} {bias:8.2f}"
              f"{flag}")
        rows.append({"instrumentation": case.instrumentation.name, "parameter": name,
                     "predicted": pred, "empirical": emp, "ratio": ratio, "seeds": n})
    print(f"within 15 %: {within15} of {len(names)}; outside the {lo:.2f}-{hi:.2f} band: "
          f"{len(outside)} of {len(names)} (about {0.05 * len(names):.1f} expected by chance)")
    return est, {"converged": n, "seeds": len(runs), "parameters": len(names),
                 "within_15_percent": within15, "band": f"{lo:.2f}-{hi:.2f}",
                 "outside_band": len(outside),
                 "ratio_range": f"{min(ratios):.2f}-{max(ratios):.2f}",
                 "outside": "; ".join(outside) or "none"}


def confirm(found: TestDesign, cases: list[Prediction], estimates: dict[str, np.ndarray],
            seeds: dict[str, list[int]], seed: int = BOOTSTRAP_SEED) -> dict:
    """Per change: predicted and empirical mean sigma removed from the interest parameters,
    the empirical one with a bootstrap interval (draws seeded by `seed`) over the seeds all
    cases converged on.  Return those figures and whether the top-ranked change is confirmed."""
    base = cases[0]
    idx = {c.instrumentation.name: [c.covariance.names.index(n) for n in found.interest]
           for c in cases}
    common = sorted(set.intersection(*(set(s) for s in seeds.values())))
    pick = {k: [seeds[k].index(s) for s in common] for k in seeds}
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(common), (BOOTSTRAP, len(common)))

    def removed(name: str, rows: np.ndarray) -> float:
        first = base.instrumentation.name
        b = estimates[first][pick[first]][rows][:, idx[first]]
        c = estimates[name][pick[name]][rows][:, idx[name]]
        return float(np.mean(1.0 - np.std(c, axis=0, ddof=1) / np.std(b, axis=0, ddof=1)))

    print(f"\n## ranking confirmed by simulation ({len(common)} seeds common to all; "
          f"interest: {', '.join(found.interest)})")
    print(f"{'change':60s} {'predicted':>9s} {'empirical':>9s}  95 % (bootstrap)")
    best, changes = None, {}
    for case in cases[1:]:
        name = case.instrumentation.name
        pred = float(np.mean([1 - case.sigma(n) / base.sigma(n) for n in found.interest]))
        emp = removed(name, np.arange(len(common)))
        boot = [removed(name, d) for d in draws]
        print(f"{name:60s} {pred:9.3f} {emp:9.3f}  {np.percentile(boot, 2.5):.3f}-"
              f"{np.percentile(boot, 97.5):.3f}")
        changes[name] = {"predicted": pred, "empirical": emp,
                         "bootstrap_95": f"{np.percentile(boot, 2.5):.3f}-"
                                         f"{np.percentile(boot, 97.5):.3f}"}
        best = best if best is not None and best[1] >= emp else (name, emp)
    top = cases[1].instrumentation.name
    print(f"top-ranked change: {top}; largest empirical reduction: {best[0] if best else '-'}"
          f" -> {'confirmed' if best and best[0] == top else 'NOT confirmed'}")
    return {"seeds": len(common), "removed": changes, "top_ranked": top,
            "confirmed": bool(best and best[0] == top)}


def main() -> int:
    parser = harness.parser(__doc__, seed=BOOTSTRAP_SEED, seed_help="seed of the bootstrap draws")
    parser.add_argument("plan", type=Path)
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--first", type=int, default=1, help="the first seed (1)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--changes", nargs="*", default=[])
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    timer = harness.Timer()
    with timer("design"):
        plan = load_plan(args.plan)
        found = design(plan)
        cases = chosen_cases(found, args.changes)
    print(f"design of {plan.problem.name}: {len(found.ranking)} changes ranked in "
          f"{timer['design']:.0f} s; flying: "
          + "; ".join(c.instrumentation.name for c in cases))
    runs = flown(plan.problem, cases, list(range(args.first, args.first + args.seeds)),
                 args.workers)
    rows: list[dict] = []
    estimates, seeds, tables = {}, {}, {}
    for case in cases:
        name = case.instrumentation.name
        estimates[name], tables[name] = table(case, runs[name], rows)
        seeds[name] = [r["seed"] for r in runs[name] if "estimates" in r]
        for r in runs[name]:
            if "error" in r:
                print(f"seed {r['seed']}: {r['error']}")
    confirmed = confirm(found, cases, estimates, seeds, args.seed)
    print(f"\nwall time {timer.elapsed():.0f} s")
    if args.out:
        with args.out.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    # one record per plan and first seed: benchmarks/results/design_validation-PLAN[-FIRST]
    name = "-".join(["design_validation", args.plan.stem.lower(),
                     *([str(args.first)] if args.first != 1 else [])])
    harness.report(name, plan=str(args.plan), design_s=timer["design"],
                   wall_s=timer.elapsed(), instrumentations=tables, ranking=confirmed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
