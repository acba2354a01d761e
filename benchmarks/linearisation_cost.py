"""Benchmark: the cost of linearising the estimation problem, function buffer against DM.

`linearise` evaluates the weighted residuals with their Jacobian and the
constraints with theirs at a point; the statistical stopping test, every
covariance, profile step and score test start from it.  Both ways of getting
the values into NumPy/SciPy are timed in this process on the same estimator
and point (the reduction's start; each problem simulated with seed 1 unless
`--seed`), best of `--repeat`:

* ``dm``: the function called with a vector, its DM outputs copied out of
  Python lists (the earlier path, `via_dm` below);
* ``buffer``: CasADi's function buffer writing into preallocated arrays on
  a pattern converted once (`function_buffer.FunctionBuffer`, the default).

    python benchmarks/linearisation_cost.py [--problems drogue drogue_full ...] [--repeat 5]
                                            [--seed 1]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca
import harness
import numpy as np
import scipy.sparse as sp

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.function_buffer import FunctionBuffer
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem


def via_dm(fn: ca.Function, z: np.ndarray) -> list[np.ndarray | sp.csc_matrix]:
    """`fn(z)` through CasADi's DM objects: vectors as NumPy, matrices as SciPy CSC."""
    return [np.asarray(ca.DM(out)).ravel() if out.shape[1] == 1 else
            sp.csc_matrix((np.asarray(out.nonzeros()), np.asarray(out.sparsity().row()),
                           np.asarray(out.sparsity().colind())), shape=out.shape)
            for out in fn(z)]


def best(evaluations: list, z: np.ndarray, repeat: int) -> float:
    """Fastest of `repeat` calls of every evaluation in `evaluations` at `z` (s)."""
    timer = harness.Timer()
    for _ in range(repeat):
        with timer("all"):
            for evaluation in evaluations:
                evaluation(z)
    return min(timer.laps["all"])


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated tests")
    parser.add_argument("--problems", nargs="+", default=["drogue", "drogue_full"])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"{'problem':12s} {'Jacobian nonzeros':>18s} {'dm s':>8s} {'buffer s':>9s} {'ratio':>6s}")
    problems = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.problems:
            folder = Path(tmp) / name
            simulate_problem(load_problem(name), folder, args.seed)
            est = Estimator(load_test(folder))
            z = est.initial_point()
            own = est.transcription.functions
            functions = (own.residual_jacobian, own.constraints)
            dm = [lambda z, f=f: via_dm(f, z) for f in functions]
            buffers = [FunctionBuffer(f) for f in functions]
            old = [evaluation(z) for evaluation in dm]
            new = [buffer(z) for buffer in buffers]
            for a, b in zip(old, new, strict=True):  # the same numbers either way
                assert np.array_equal(a[0], b[0]) and (a[1] != b[1]).nnz == 0
            nnz = sum(out[1].nnz for out in new)
            t_dm = best(dm, z, args.repeat)
            t_buf = best(buffers, z, args.repeat)
            problems[name] = {"jacobian_nonzeros": nnz, "dm_s": t_dm, "buffer_s": t_buf,
                              "buffer_over_dm": harness.ratio(t_buf, t_dm)}
            print(f"{name:12s} {nnz:18,d} {t_dm:8.3f} {t_buf:9.3f} "
                  f"{problems[name]['buffer_over_dm']:6.2f}", flush=True)
    harness.report("linearisation_cost", repeat=args.repeat, problems=problems)


if __name__ == "__main__":
    main()
