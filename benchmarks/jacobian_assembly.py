"""Benchmark: stacking the blocks' Jacobians through one gather of nonzeros, against CasADi's
vertcat and row indexing of the sparse matrices (`estimation/sparse_rows.py`).

The `drogue` test (simulated once, seed 4 unless `--seed`) is transcribed
twice in one process, with `sparse_rows.ONE_GATHER` off (the earlier path)
and on, each with native pieces (`CPAS_OCP_COMPILE=wait`, compiled once into a
temporary cache before any timing) and in CasADi's VM.  Printed per path: the
estimator's build time, the time of one
evaluation of the residuals with their Jacobian (rJ) and of the constraints
with theirs (gA), the median of `--repeats`, and the wall time and chi-square
of a fit from the offline reduction; then the ratios earlier / one gather.

    python benchmarks/jacobian_assembly.py [--seed N] [--repeats N]
"""

from __future__ import annotations

import os
import statistics
import tempfile
from pathlib import Path

import harness
import numpy as np

from cpas_ocp.estimation import sparse_rows
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem


def measure(folder: Path, repeats: int) -> dict[str, float]:
    """The estimator's build time (s), per-evaluation times (ms) of rJ and gA at the starting
    point, and one fit's time (s) and chi-square."""
    timer = harness.Timer()
    with timer("build"):
        est = Estimator(load_test(folder), baseline_spec())
    out = {"build": timer["build"]}
    z = est.initial_point()
    for name in ("rJ", "gA"):
        buffer = est.transcription.points._buffers[name]
        buffer.nonzeros(z)
        for _ in range(repeats):
            with timer(name):
                buffer.nonzeros(z)
        out[name] = 1e3 * statistics.median(timer.laps[name])
    with timer("fit"):
        fit = est.solve()
    out["fit"] = timer["fit"]
    out["chi2"] = fit.chi_square
    return out


def main() -> None:
    parser = harness.parser(__doc__, seed=4, seed_help="seed of the simulated drogue test")
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "drogue"
        simulate_problem(load_problem("drogue"), folder, args.seed)
        os.environ["CPAS_OCP_CACHE"] = str(Path(tmp) / "cache")
        results = {}
        os.environ["CPAS_OCP_COMPILE"] = "wait"
        Estimator(load_test(folder), baseline_spec())  # the pieces compiled, untimed
        for mode in ("wait", "0"):
            os.environ["CPAS_OCP_COMPILE"] = mode
            for one_gather in (False, True):
                sparse_rows.ONE_GATHER = one_gather
                results[mode, one_gather] = measure(folder, args.repeats)
    print(f"drogue seed {args.seed}: one evaluation (median of {args.repeats}) and one fit")
    print(f"{'code':8} {'stacking':12} {'build (s)':>9} {'rJ (ms)':>8} {'gA (ms)':>8} "
          f"{'fit (s)':>8} {'chi2':>10}")
    for (mode, one_gather), r in results.items():
        print(f"{'native' if mode == 'wait' else 'VM':8} "
              f"{'one gather' if one_gather else 'vertcat':12} {r['build']:9.2f} "
              f"{r['rJ']:8.1f} {r['gA']:8.1f} "
              f"{r['fit']:8.2f} {r['chi2']:10.3f}")
    summary = {}
    for mode in ("wait", "0"):
        old, new = results[mode, False], results[mode, True]
        code = "native" if mode == "wait" else "VM"
        ratios = {k: harness.ratio(old[k], new[k]) for k in ("build", "rJ", "gA", "fit")}
        same = np.isclose(old["chi2"], new["chi2"], rtol=1e-6)
        summary[code] = {"vertcat": old, "one_gather": new, "vertcat_over_one_gather": ratios,
                         "same_chi_square": same}
        print(f"{code}: vertcat / one gather: "
              f"{'  '.join(f'{k} {v:.2f}' for k, v in ratios.items())}; same chi-square: {same}")
    harness.report("jacobian_assembly", repeats=args.repeats, code=summary)


if __name__ == "__main__":
    main()
