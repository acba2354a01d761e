"""Reliability: the numerical tests under several OpenBLAS kernels, in fresh processes.

Which of two equal numbers comes out larger, and the last bits of every
factorisation, depend on the BLAS kernel the machine picks; a report or a test
that leans on them passes on one machine and fails on another (the
undetermined-combination test once failed under Haswell and Zen kernels).
This runs the tests that reach the linear algebra (`--tests`, by default the
KKT, identifiability, covariance, stopping and descent tests) once per kernel
named (`OPENBLAS_CORETYPE`; default: the machine's own, Haswell, Zen, Prescott)
and prints each run's outcome and wall time.  The whole suite can be given as
`--tests tests`.

    python benchmarks/blas_kernels.py [--kernels default Haswell Zen Prescott]
                                      [--tests tests/estimation/test_kkt.py ...]
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import harness

ROOT = Path(__file__).resolve().parents[1]
TESTS = ["tests/estimation/test_kkt.py", "tests/estimation/test_identifiability.py",
         "benchmarks/studies/test_coverage.py", "tests/estimation/test_stopping.py",
         "tests/estimation/test_feasible_descent.py", "tests/estimation/test_exact_hessian.py"]


def main() -> int:
    parser = harness.parser(__doc__, seed=None,
                            seed_help="recorded only: nothing here is drawn at random")
    parser.add_argument("--kernels", nargs="+", default=["default", "Haswell", "Zen", "Prescott"])
    parser.add_argument("--tests", nargs="+", default=TESTS)
    args = parser.parse_args()
    failed = 0
    timer = harness.Timer()
    runs = []
    for kernel in args.kernels:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel != "default":
            env["OPENBLAS_CORETYPE"] = kernel
        with timer(kernel):
            done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                   *args.tests], env=env, cwd=ROOT, capture_output=True,
                                  text=True)
        summary = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
        print(f"{kernel:>10}: {summary}  ({timer[kernel]:.1f} s)", flush=True)
        failed += done.returncode != 0
        runs.append({"kernel": kernel, "passed": done.returncode == 0, "summary": summary,
                     "wall_s": timer[kernel]})
    print("every kernel passed" if not failed else f"{failed} kernel(s) FAILED")
    harness.report("blas_kernels", kernels=runs, failed=failed)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
