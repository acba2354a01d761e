"""Benchmark: what the bound of a GPS lag costs, with the steps fixed and with steps set by it.

The `drogue` problem is simulated (seed 1 unless `--seed`) with a 0.25 s GPS lag and
fitted with the baseline model plus `SensorLag(max_lag=B)` for each bound B, each
fit in a fresh process with an empty compile cache, so that its peak memory
(the process's and the compiler's) and its build and solve times are its
own.  Each bound is run with this tree's code and, given `--baseline REV`,
with the code of that git revision (checked out in a temporary worktree),
and the ratios printed against the current code at the smallest bound.

    python benchmarks/lag_bound_cost.py [--bounds 0.2 0.3 0.5] [--baseline REV] [--seed 1]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
from revisions import ROOT, code_at, run_child

CHILD = r"""
import dataclasses, json, resource, sys, time
from pathlib import Path

from cpas_ocp.estimation import estimator as estimation
from cpas_ocp.physics.effects import SensorLag, baseline_effects
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.estimation.simulate import simulate_problem

folder, bound, seed = Path(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
if not folder.exists():
    problem = load_problem("drogue")
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, "lag[gps]": 0.25}),
                     folder, seed, effects=[*baseline_effects(), SensorLag(max_lag=0.5)])
t0 = time.perf_counter()
est = Estimator(load_test(folder), [*baseline_effects(), SensorLag(max_lag=bound)])
build = time.perf_counter() - t0
t0 = time.perf_counter()
try:
    fit = est.solve()
    outcome = {"chi2": fit.chi_square, "iterations": fit.solver.iterations,
               "lag": fit.parameters["lag[gps]"]}
except SolverFailure as exc:
    outcome = {"failed": str(exc)}
solve = time.perf_counter() - t0
own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
compiler = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
print(json.dumps({"code": str(Path(estimation.__file__).parent), "build_s": build,
                  "solve_s": solve, "peak_gb": own, "compiler_peak_gb": compiler, **outcome}))
"""


def run(code_root: Path, folder: Path, bound: float, seed: int = 1) -> dict:
    """One fit in a fresh process importing cpas_ocp from `code_root`, with an empty cache
    (the test simulated with `seed` into `folder` first where it is not there)."""
    return run_child(CHILD, code_root, str(folder), str(bound), str(seed))


def _peak(result: dict) -> float:
    """The larger of the fit's and the compiler's peak resident memory (GB)."""
    return max(result["peak_gb"], result["compiler_peak_gb"])


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue test")
    parser.add_argument("--bounds", type=float, nargs="+", default=[0.2, 0.3, 0.5])
    parser.add_argument("--baseline", help="git revision whose code is run as well")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp, code_at(args.baseline) as baseline:
        roots = {"current": ROOT, **({args.baseline: baseline} if args.baseline else {})}
        folder = Path(tmp) / "drogue-lag"
        reference, runs = None, []
        for label, root in roots.items():
            for bound in sorted(args.bounds):
                r = run(root, folder, bound, args.seed)
                reference = reference or r
                r |= {"code_label": label, "bound_s": bound,
                      "memory_ratio": harness.ratio(_peak(r), _peak(reference)),
                      "build_ratio": harness.ratio(r["build_s"], reference["build_s"])}
                runs.append(r)
                fit = (f"failed: {r['failed']}" if "failed" in r else
                       f"{r['iterations']} it, chi-square {r['chi2']:.2f}, "
                       f"lag {r['lag']:.4f} s")
                print(f"{label:>10s} +-{bound:.2f} s: build {r['build_s']:6.1f} s, solve "
                      f"{r['solve_s']:6.1f} s, peak {r['peak_gb']:.2f} GB (compiler "
                      f"{r['compiler_peak_gb']:.2f} GB); memory ratio "
                      f"{r['memory_ratio']:.2f}, build ratio "
                      f"{r['build_ratio']:.2f}; {fit} [{r['code']}]",
                      flush=True)
    harness.report("lag_bound_cost", baseline=args.baseline, runs=runs)

if __name__ == "__main__":
    main()
