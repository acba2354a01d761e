"""Benchmark: wall time and peak memory per built-in problem, and solve time against samples.

Part 1: each built-in problem is simulated (seed 1 unless `--seed`, as in part 2)
and reconstructed with default settings in a fresh subprocess, so that its peak
resident memory (``VmHWM``, the high-water mark of this process image alone) is
its own.
The compiled model functions are built once beforehand, outside the timing.
The covariance is timed against the solve it follows, in the same process:
the Gauss-Newton one always, the exact-Hessian one with ``--exact``.

Part 2: the `fbcp` problem with its IMU and load cells sampled at 100 Hz to
4 kHz (GPS stays at 10 Hz), i.e. about 1,200 to 48,000 residuals, on a fixed
5 ms shooting grid, so that only the number of samples changes.  Ratios are
against the smallest run in this same invocation: time per Ipopt iteration
and samples, whose log-log slope is the growth exponent (1 = linear).

    python benchmarks/problem_scaling.py [--problems drogue pilot ...] [--rates 100 250 ...]
                                         [--exact] [--seed 1]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import harness
import numpy as np

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem, problem_names


def run_one(folder: Path, grid_step: float | None, exact: bool = False) -> dict:
    """Build and solve one test folder; the caller runs this in a fresh process."""
    test = load_test(folder)
    timer = harness.Timer()
    with timer("build"):
        est = Estimator(test, settings=Settings(grid_step=grid_step))
    fit = est.solve(progress=False)
    with timer("covariance"):
        est.covariance(fit)
    if exact:
        with timer("exact"):
            est.covariance(fit, hessian="exact")
    return {"samples": fit.n_samples, "variables": int(est.transcription.z.numel()),
            "build_s": timer["build"],
            "solve_s": fit.solver.wall_s, "covariance_s": timer["covariance"],
            "exact_s": timer["exact"] if exact else None,
            "iterations": fit.solver.iterations, "status": fit.solver.status,
            "peak_mb": peak_memory_mb()}


# Problems measured by their own study: a reconstruction from the reduction alone is
# not what those scripts time.
MEASURED_ELSEWHERE = {"main3_full": "benchmarks/main3_effect_omission.py"}


def peak_memory_mb() -> float:
    """Peak resident memory of this process image (MB).

    ``VmHWM`` from /proc: ``ru_maxrss`` would carry over the parent's peak,
    since a forked child starts out sharing all of the parent's pages and Linux
    keeps that high-water mark across exec.
    """
    status = Path("/proc/self/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def in_subprocess(folder: Path, grid_step: float | None, exact: bool = False) -> dict:
    cmd = [sys.executable, __file__, "--one", str(folder)]
    if grid_step is not None:
        cmd += ["--grid-step", str(grid_step)]
    if exact:
        cmd += ["--exact"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def with_rate(name: str, rate: float):
    problem = load_problem(name)
    rates = {k: (v if k == "gps" else rate) for k, v in problem.simulation["rates_hz"].items()}
    return dataclasses.replace(problem, simulation={**problem.simulation, "rates_hz": rates})


def main() -> None:
    ap = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    ap.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--grid-step", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--problems", nargs="+", default=None,
                    help="built-in problems to time (default: all but " +
                    ", ".join(MEASURED_ELSEWHERE) + ")")
    ap.add_argument("--rates", type=float, nargs="*", default=[100, 250, 500, 1000, 2000, 4000],
                    help="IMU and load-cell rates of the fbcp scaling runs (none: skip them)")
    ap.add_argument("--exact", action="store_true",
                    help="also time the exact-Hessian covariance")
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.grid_step, args.exact)))
        return

    tmp = Path(tempfile.mkdtemp(prefix="cpas-bench-"))
    print(f"per problem (seed {args.seed}, default settings, fresh process each):")
    print(f"{'problem':8s} {'samples':>8s} {'variables':>9s} {'build s':>8s} {'solve s':>8s} "
          f"{'iter':>5s} {'cov s':>6s} {'cov/solve':>9s} {'exact s':>8s} {'exact/solve':>11s} "
          f"{'peak MB':>8s}")
    names = args.problems or [n for n in problem_names() if n not in MEASURED_ELSEWHERE]
    problems: dict[str, dict] = {}
    for name in sorted(set(MEASURED_ELSEWHERE) - set(names)):
        print(f"{name:8s} timed by {MEASURED_ELSEWHERE[name]}")
    for name in names:
        folder = tmp / name
        simulate_problem(load_problem(name), folder, seed=args.seed)
        Estimator(load_test(folder))  # compile (cached) outside the timing
        r = problems[name] = in_subprocess(folder, None, args.exact)
        r["covariance_over_solve"] = harness.ratio(r["covariance_s"], r["solve_s"])
        r["exact_over_solve"] = harness.ratio(r["exact_s"], r["solve_s"]) if args.exact else None
        exact = (f"{r['exact_s']:8.1f} {r['exact_over_solve']:11.2f}" if args.exact
                 else f"{'-':>8s} {'-':>11s}")
        print(f"{name:8s} {r['samples']:8d} {r['variables']:9d} {r['build_s']:8.1f} "
              f"{r['solve_s']:8.1f} {r['iterations']:5d} {r['covariance_s']:6.1f} "
              f"{r['covariance_over_solve']:9.3f} {exact} "
              f"{r['peak_mb']:8.0f}   {r['status']}", flush=True)

    if not args.rates:
        harness.report("problem_scaling", problems=problems)
        return
    print("\nfbcp, 5 ms grid, IMU and load-cell rate varied (fresh process each):")
    print(f"{'rate Hz':>8s} {'samples':>8s} {'solve s':>8s} {'iter':>5s} {'s/iter':>7s} "
          f"{'ratio':>6s} {'samples ratio':>13s} {'peak MB':>8s}")
    rows, scaling = [], []
    for rate in args.rates:
        folder = tmp / f"fbcp-{rate:g}"
        simulate_problem(with_rate("fbcp", rate), folder, seed=args.seed)
        if not rows:
            Estimator(load_test(folder), settings=Settings(grid_step=0.005))
        r = in_subprocess(folder, 0.005)
        per_iter = r["solve_s"] / r["iterations"]
        rows.append((r["samples"], per_iter))
        scaling.append({"rate_hz": rate, **r, "s_per_iteration": per_iter,
                        "ratio": harness.ratio(per_iter, rows[0][1]),
                        "samples_ratio": harness.ratio(r["samples"], rows[0][0])})
        print(f"{rate:8g} {r['samples']:8d} {r['solve_s']:8.2f} {r['iterations']:5d} "
              f"{per_iter:7.3f} {scaling[-1]['ratio']:6.2f} {scaling[-1]['samples_ratio']:13.1f} "
              f"{r['peak_mb']:8.0f}", flush=True)
    n, t = np.log([r[0] for r in rows]), np.log([r[1] for r in rows])
    slope = np.polyfit(n, t, 1)[0]
    print(f"\ngrowth exponent of time per iteration in samples (log-log slope): {slope:.2f}")
    harness.report("problem_scaling", problems=problems, scaling=scaling, growth_exponent=slope)


if __name__ == "__main__":
    main()
