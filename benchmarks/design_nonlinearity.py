"""Benchmark: is the excess spread of five `drogue` parameters over the design's prediction
explained by the likelihood's nonlinearity, or by the event-time noise?

`cpas-ocp design` predicts each parameter's sigma from the Fisher information at the
nominal parameters.  Over 50 seeds (`benchmarks/design_validation.py`) five parameters of
the planned `drogue` test spread 1.18-1.33 times that prediction in every instrumentation:
n_p, expopen and t_start of drogue1's second stage, Ck and t_k of drogue2's second stage.
Two measurements on the plan's first candidate (the test as planned):

1. The spread, on --seeds seeds from --first: each seed flown as in
   `design_validation.fly` (sensor and event-timing noise from the seed, truth.json out
   of the folder, ``Estimator(load_test(folder)).solve()``), and the same seed flown again
   with the events' timing noise removed (every event at its true time, sigma
   EXACT_EVENT_SIGMA): the same sensor noise, since the simulator draws the events'
   timing noise first and always the same number of draws.  Per parameter: the predicted
   sigma, the empirical/predicted ratio with and without event noise, each with its 95 %
   interval (the sample sd of N Gaussian draws: ratio * sqrt((N-1) / chi2_{N-1})), the
   paired difference's sd over the predicted sigma (what the event-time noise alone
   moves the estimate), the mean per-seed Wald sigma over the prediction, the robust
   ratio (1.4826 median absolute deviation over the prediction: near 1 where a few far
   seeds make the excess, near the ratio where the whole distribution is wider), the
   largest |estimate - truth| over the prediction, the bias over its standard error, the
   correlation of the error with the seed's own Wald sigma (r(W): how far the information
   changes along the parameter, the nonlinearity a nominal-point prediction cannot show),
   and the sd of the error over the seed's own Wald sigma ("own").
   The five's joint excess is tested against seeded Gaussian draws of N seeds from the
   predicted covariance (their correlations included; `--seed`): the share of draws whose mean of
   ln(s^2 / sigma^2) over the five reaches the observed one.  Seeds beyond 50 were not
   seen when the five were named, so on them the test is free of the selection.
2. The profile likelihood (`inference.profile_likelihood.profile`, what
   `Reconstruction.profile` does) of the five and of CONTROLS (parameters the prediction
   got right) on --profile-seeds, over the estimate -+ --span sigma at --points values.
   Each side's 95 % edge is where the signed root of delta chi-square reaches
   sqrt(3.84) = 1.96, interpolated linearly in that root (exact for a parabola, so the
   grid's coarseness biases no edge); the half-widths below and above, over the Wald
   half-width 1.96 sigma of the seed's own covariance.  A profile wider than Wald by the
   excess factor would explain it; a profile at 1.00 says the likelihood is quadratic
   there and the excess comes from elsewhere.

    python benchmarks/design_nonlinearity.py docs/plans/drogue.json --seeds 100 --paired \
        --profile-seeds 1 2 3 4 --workers 2 [--first 1] [--out JSON] [--runs JSON ...]

--out keeps every seed's estimates and profiles; --runs reads such a file back instead of
flying again.  A `drogue` fit takes about 3 s on one core, a profile point about 4 s.
"""

from __future__ import annotations

import argparse
import dataclasses
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
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.flight_test_design import Planner, Prediction, planned_problem
from cpas_ocp.inference.profile_likelihood import THRESHOLD, profile
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.flight_test_plan import Instrumentation, load_plan
from cpas_ocp.io.problems import Problem

FOCUS = ("n_p[drogue1,stage2]", "expopen[drogue1,stage2]", "t_start[drogue1,stage2]",
         "Ck[drogue2,stage2]", "t_k[drogue2,stage2]")
CONTROLS = ("Ck[drogue1,stage1]", "n_p[drogue1,stage1]", "t_start[drogue2,stage3]")
EXACT_EVENT_SIGMA = 1e-6  # s: an event's timing sigma when its noise is removed
NULL_DRAWS = 20000  # Gaussian draws of N seeds for the joint test
NULL_SEED = 20261201  # the default --seed
NULL_CHUNK = 1000  # draws made at once
SELECTION_SEEDS = 50  # the seeds on which the five were named
MAD_TO_SD = 1.4826  # median absolute deviation to the sd of a Gaussian


def flown_problem(problem: Problem, instr: Instrumentation, event_noise: bool) -> Problem:
    """`problem` flown with `instr`; without `event_noise`, every event at its true time
    (timing sigma EXACT_EVENT_SIGMA s, the draws still made, so the sensor noise of a seed
    is unchanged)."""
    flown = planned_problem(problem, instr)
    if event_noise:
        return flown
    events = [{**e, "sigma": EXACT_EVENT_SIGMA} for e in flown.simulation.get("events", [])]
    return dataclasses.replace(flown, simulation={**flown.simulation, "events": events})


def fit_seed(problem: Problem, instr: Instrumentation, seed: int, event_noise: bool,
             profiled: tuple[str, ...] = (), span: float = 3.0, points: int = 9) -> dict:
    """One seed: the estimates and Wald sigmas (SI) by name, the truth, and the profiles
    of `profiled` (values, delta chi-square); or the solver's failure."""
    with tempfile.TemporaryDirectory(prefix="cpas-design-nl-") as tmp:
        folder = Path(tmp) / "test"
        simulate_problem(flown_problem(problem, instr, event_noise), folder, seed,
                         known_only=True)
        (folder / "truth.json").rename(Path(tmp) / "truth.json")  # out of the estimator's reach
        est = Estimator(load_test(folder))
        try:
            fit = est.solve()
        except SolverFailure as err:
            return {"seed": seed, "event_noise": event_noise, "error": str(err)}
        cov = est.covariance(fit)
        truth = json.loads((Path(tmp) / "truth.json").read_text())["parameters"]
        out = {"seed": seed, "event_noise": event_noise,
               "estimates": {n: fit.parameters[n] for n in fit.free},
               "wald": {n: cov.std.get(n) for n in fit.free},
               "truth": {n: truth[n] for n in fit.free}, "profiles": {}}
        for name in profiled:
            prof = profile(est, fit, cov, name, span, points)
            out["profiles"][name] = {"values": prof.values.tolist(),
                                     "delta": prof.delta_chi_square.tolist(),
                                     "failures": len(prof.failures)}
        return out


def run_all(problem: Problem, instr: Instrumentation, args: argparse.Namespace) -> list[dict]:
    """The spread's fits (each seed with event noise, and without where --paired) and the
    profiles'."""
    seeds = range(args.first, args.first + args.seeds)
    jobs = [(s, noise, ()) for s in seeds for noise in ((True, False) if args.paired
                                                       else (True,))]
    jobs += [(s, True, FOCUS + CONTROLS) for s in args.profile_seeds]
    out = []
    end = "\r" if sys.stderr.isatty() else "\n"
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        futures = [pool.submit(fit_seed, problem, instr, s, noise, prof, args.span,
                               args.points) for s, noise, prof in reversed(jobs)]
        for k, future in enumerate(as_completed(futures), 1):
            out.append(future.result())
            print(f"fits done {k}/{len(futures)}", end=end, file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return sorted(out, key=lambda r: (r["seed"], not r["event_noise"], len(r["profiles"])
                                      if "profiles" in r else 0))


def ratio_interval(ratio: float, n: int) -> tuple[float, float]:
    """The 95 % interval of the true sd over the predicted one, given the sample sd over
    the predicted `ratio` from `n` Gaussian draws."""
    lo, hi = np.sqrt((n - 1) / chi2.ppf([0.975, 0.025], n - 1))
    return ratio * float(lo), ratio * float(hi)


def joint_excess(est: np.ndarray, cov: np.ndarray, seed: int = NULL_SEED
                 ) -> tuple[float, float]:
    """Mean over the columns of ln(s^2 / sigma^2) of the estimates `est` (seeds x
    parameters) against the predicted covariance `cov`, and the share of NULL_DRAWS
    Gaussian draws (seeded by `seed`) of as many seeds from `cov` that reach it (one-sided
    p)."""
    sigma2 = np.diag(cov)
    observed = float(np.mean(np.log(np.var(est, axis=0, ddof=1) / sigma2)))
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal(np.zeros(len(sigma2)), cov, size=(NULL_DRAWS, len(est)))
    null = np.mean(np.log(np.var(draws, axis=1, ddof=1) / sigma2), axis=1)
    return observed, float(np.mean(null >= observed))


def selected_excess(est: np.ndarray, cov: np.ndarray, k: int, seed: int = NULL_SEED
                    ) -> tuple[float, float]:
    """Mean of the `k` largest ln(s^2 / sigma^2) over every parameter (columns of `est`,
    seeds x parameters, against the predicted covariance `cov`), and the share of
    NULL_DRAWS Gaussian draws (seeded by `seed`) of as many seeds from `cov` whose own `k`
    largest reach it: the joint test of `k` parameters named after the fact for spreading
    most."""
    sigma2 = np.diag(cov)
    top = lambda s2: np.mean(np.sort(np.log(s2 / sigma2), axis=-1)[..., -k:], axis=-1)  # noqa: E731
    observed = float(top(np.var(est, axis=0, ddof=1)))
    rng = np.random.default_rng(seed)
    null = []
    for _ in range(NULL_DRAWS // NULL_CHUNK):
        draws = rng.multivariate_normal(np.zeros(len(sigma2)), cov,
                                        size=(NULL_CHUNK, len(est)), method="eigh")
        null.append(top(np.var(draws, axis=1, ddof=1)))
    return observed, float(np.mean(np.concatenate(null) >= observed))


def root_edge(values: np.ndarray, delta: np.ndarray, estimate: float) -> float | None:
    """Distance from `estimate` to the first of `values` (walking out, one side) where the
    signed root of delta chi-square reaches sqrt(THRESHOLD), interpolated linearly in the
    root; None where the profile stays below it."""
    target = float(np.sqrt(THRESHOLD))
    v_prev, r_prev = estimate, 0.0
    for v, d in zip(values, delta, strict=True):
        r = float(np.sqrt(max(d, 0.0)))
        if r >= target:
            return abs(v_prev + (target - r_prev) * (v - v_prev) / (r - r_prev) - estimate)
        v_prev, r_prev = v, r
    return None


def profile_edges(prof: dict, estimate: float) -> tuple[float | None, float | None]:
    """The profile's 95 % half-widths below and above the estimate (SI)."""
    v, d = np.asarray(prof["values"]), np.asarray(prof["delta"])
    below, above = v < estimate, v > estimate
    return (root_edge(v[below][::-1], d[below][::-1], estimate),
            root_edge(v[above], d[above], estimate))


def spread_table(pred: Prediction, runs: list[dict], names: tuple[str, ...]
                 ) -> dict[str, dict[str, float]]:
    """Print, per name, over the seeds flown with event noise, the empirical/predicted ratio
    (95 % interval), the mean Wald sigma, the robust ratio, the largest error, the bias, the
    error's correlation with the seed's Wald sigma and its sd in units of that sigma;
    the ratio on the seeds that named the five and on the rest; over the seeds also flown
    without it, that ratio and the paired difference's sd.
    Return each name's figures (the ratio with event noise first)."""
    spread = [r for r in runs if "estimates" in r and not r["profiles"]]
    noisy = {r["seed"]: r for r in spread if r["event_noise"]}
    exact = {r["seed"]: r for r in spread if not r["event_noise"]}
    seeds, pairs = sorted(noisy), sorted(set(noisy) & set(exact))
    n, m = len(seeds), len(pairs)
    print(f"\n## spread over seeds {seeds[0]}-{seeds[-1]}: {n} converged with event noise, "
          f"{m} of them also without")
    print(f"{'parameter':26s} {'predicted':>10s} {'ratio':>5s} {'95 %':>10s} {'Wald':>5s} "
          f"{'robust':>6s} {'max|z|':>6s} {'bias/se':>7s} {'r(W)':>5s} {'own':>5s} "
          f"{'1-50':>5s} {'51-':>5s} {'no ev.':>6s} {'paired':>6s}")
    rows: dict[str, dict[str, float]] = {}
    for name in names:
        sigma = pred.sigma(name)
        a = np.array([noisy[s]["estimates"][name] for s in seeds])
        err = a - np.array([noisy[s]["truth"][name] for s in seeds])
        ratio = float(np.std(a, ddof=1) / sigma)
        lo, hi = ratio_interval(ratio, n)
        own = np.array([noisy[s]["wald"][name] for s in seeds])
        wald = np.mean(own) / sigma
        robust = MAD_TO_SD * np.median(np.abs(a - np.median(a))) / sigma
        rows[name] = {"predicted": sigma, "ratio": ratio, "ratio_95": f"{lo:.2f}-{hi:.2f}",
                      "wald": float(wald), "robust": float(robust),
                      "r_error_own_sigma": float(np.corrcoef(err, own)[0, 1]),
                      "sd_in_own_sigma": float(np.std(err / own, ddof=1))}
        line = (f"{name:26s} {sigma:10.4g} {ratio:5.2f} {lo:4.2f}-{hi:4.2f} {wald:5.2f} "
                f"{robust:6.2f} {np.max(np.abs(err)) / sigma:6.2f} "
                f"{np.mean(err) / (np.std(a, ddof=1) / np.sqrt(n)):7.2f} "
                f"{np.corrcoef(err, own)[0, 1]:5.2f} {np.std(err / own, ddof=1):5.2f}")
        named = np.array(seeds) <= SELECTION_SEEDS  # the seeds that named the five
        for key, part in ((f"ratio_seeds_1_{SELECTION_SEEDS}", a[named]),
                          (f"ratio_seeds_{SELECTION_SEEDS + 1}_on", a[~named])):
            rows[name][key] = float(np.std(part, ddof=1) / sigma) if len(part) > 2 else None
            line += f" {rows[name][key]:5.2f}" if len(part) > 2 else f" {'-':>5s}"
        if m > 2:
            a2 = np.array([noisy[s]["estimates"][name] for s in pairs])
            b2 = np.array([exact[s]["estimates"][name] for s in pairs])
            rows[name] |= {"ratio_without_event_noise": float(np.std(b2, ddof=1) / sigma),
                           "paired_difference_sd": float(np.std(a2 - b2, ddof=1) / sigma)}
            line += (f" {rows[name]['ratio_without_event_noise']:6.2f} "
                     f"{rows[name]['paired_difference_sd']:6.3f}")
        print(line)
    return rows


def joint_table(pred: Prediction, runs: list[dict], seed: int = NULL_SEED) -> list[dict]:
    """The five's joint excess (`joint_excess`) per block of SELECTION_SEEDS seeds (the
    first is the one that named them) and over all; with and without event noise.  Return
    each line's figures."""
    cov = pred.covariance
    out = []
    idx = [cov.names.index(n) for n in FOCUS]
    block = cov.matrix[np.ix_(idx, idx)]
    print("\n## joint excess of the five: mean ln(s^2/sigma^2) -> ratio, one-sided p")
    for noise in (True, False):
        done = [r for r in runs if "estimates" in r and not r["profiles"]
                and r["event_noise"] == noise]
        groups = sorted({(r["seed"] - 1) // SELECTION_SEEDS for r in done})
        for g in [*groups, None]:
            est = np.array([[r["estimates"][n] for n in FOCUS] for r in done
                            if g is None or (r["seed"] - 1) // SELECTION_SEEDS == g])
            if len(est) < 3 or (g is None and len(groups) < 2):
                continue
            label = ("all seeds" if g is None else
                     f"seeds {g * SELECTION_SEEDS + 1}-{(g + 1) * SELECTION_SEEDS}")
            obs, p = joint_excess(est, block, seed)
            print(f"{'with' if noise else 'without'} event noise, {label} ({len(est)}): "
                  f"{obs:+.3f} -> {np.exp(obs / 2):.3f}, p = {p:.4f}")
            out.append({"event_noise": noise, "seeds": label, "n": len(est),
                        "mean_log_excess": obs, "ratio": float(np.exp(obs / 2)), "p": p})
            if noise and g == 0:
                full = np.array([[r["estimates"][n] for n in cov.names] for r in done
                                 if (r["seed"] - 1) // SELECTION_SEEDS == g])
                top, q = selected_excess(full, cov.matrix, len(FOCUS), seed)
                print(f"  the {len(FOCUS)} widest of all {len(cov.names)} on these seeds: "
                      f"{top:+.3f} -> {np.exp(top / 2):.3f}; p with the choice after the "
                      f"fact = {q:.4f}")
                out[-1] |= {"widest_mean_log_excess": top,
                            "widest_ratio": float(np.exp(top / 2)), "widest_p": q}
    return out


def profile_table(pred: Prediction, runs: list[dict], ratios: dict[str, float]
                  ) -> dict[str, list[float]]:
    """Print per profiled parameter and seed the Wald half-width 1.96 sigma, the profile's
    half-widths below and above, and their mean over Wald; then per parameter the mean over
    the seeds beside the empirical/predicted ratio.  Return those means (lower, upper, both
    over Wald) per parameter."""
    means = {}
    profiled = [r for r in runs if r.get("profiles")]
    failed = [r["seed"] for r in runs if "error" in r]
    print(f"\n## profiles on seeds {', '.join(str(r['seed']) for r in profiled)}"
          + (f"; fits failed on seeds {failed}" if failed else ""))
    print(f"{'parameter':26s} {'seed':>4s} {'Wald':>10s} {'lower':>10s} {'upper':>10s} "
          f"{'lo/W':>5s} {'up/W':>5s} {'prof/W':>6s} {'failed':>6s}")
    summary = {}
    for name in FOCUS + CONTROLS:
        for r in profiled:
            wald = float(np.sqrt(THRESHOLD)) * r["wald"][name]
            lo, hi = profile_edges(r["profiles"][name], r["estimates"][name])
            rel = [e / wald if e is not None else np.nan for e in (lo, hi)]
            summary.setdefault(name, []).append(rel)
            show = lambda e: f"{e:10.4g}" if e is not None else f"{'>span':>10s}"  # noqa: E731
            print(f"{name:26s} {r['seed']:4d} {wald:10.4g} {show(lo)} {show(hi)} "
                  f"{rel[0]:5.2f} {rel[1]:5.2f} {np.nanmean(rel):6.2f} "
                  f"{r['profiles'][name]['failures']:6d}")
    print(f"\n{'parameter':26s} {'predicted':>10s} {'emp/pred':>8s} {'lo/W':>5s} {'up/W':>5s} "
          f"{'prof/W':>6s}  (profile over Wald: mean over the seeds)")
    for name, rel in summary.items():
        m = np.nanmean(np.array(rel), axis=0)
        emp = f"{ratios[name]:8.2f}" if name in ratios else f"{'-':>8s}"
        print(f"{name:26s} {pred.sigma(name):10.4g} {emp} {m[0]:5.2f} {m[1]:5.2f} "
              f"{np.mean(m):6.2f}")
        means[name] = [float(m[0]), float(m[1]), float(np.mean(m))]
    return means


def main() -> int:
    parser = harness.parser(__doc__, seed=NULL_SEED,
                            seed_help="seed of the joint test's Gaussian draws")
    parser.add_argument("plan", type=Path)
    parser.add_argument("--seeds", type=int, default=0, help="number of seeds for the spread")
    parser.add_argument("--first", type=int, default=1, help="first seed of the spread")
    parser.add_argument("--paired", action="store_true",
                        help="fly each seed of the spread again without event-time noise")
    parser.add_argument("--profile-seeds", type=int, nargs="*", default=[])
    parser.add_argument("--span", type=float, default=3.0, help="profile span (sigma)")
    parser.add_argument("--points", type=int, default=9, help="profile points")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--runs", type=Path, nargs="*", default=[],
                        help="files --out wrote, read (merged) instead of flying")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    plan = load_plan(args.plan)
    instr = plan.candidates[0]
    pred = Planner(plan.problem).predict(instr)
    runs = ([r for f in args.runs for r in json.loads(f.read_text())] if args.runs
            else run_all(plan.problem, instr, args))
    if args.out:
        args.out.write_text(json.dumps(runs))
    for r in runs:
        if "error" in r:
            print(f"seed {r['seed']} (event noise {r['event_noise']}): {r['error']}")
    spread, joint, profiles = {}, [], {}
    if any(not r.get("profiles") for r in runs):
        spread = spread_table(pred, runs, FOCUS + CONTROLS)
        joint = joint_table(pred, runs, args.seed)
    if any(r.get("profiles") for r in runs):
        profiles = profile_table(pred, runs, {n: row["ratio"] for n, row in spread.items()})
    role = {name: "named" if name in FOCUS else "control" for name in FOCUS + CONTROLS}
    harness.report("design_nonlinearity", plan=str(args.plan),
                   failed=[[r["seed"], r["event_noise"]] for r in runs if "error" in r],
                   spread={name: {"role": role[name]} | row for name, row in spread.items()},
                   profiles={name: {"role": role[name]} | dict(zip(
                       ("below_over_wald", "above_over_wald", "both_over_wald"), means,
                       strict=True)) for name, means in profiles.items()},
                   joint_excess=joint)
    return 0


if __name__ == "__main__":
    sys.exit(main())
