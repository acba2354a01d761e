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

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ["tests/estimation/test_kkt.py", "tests/estimation/test_identifiability.py",
         "tests/studies/test_coverage.py", "tests/estimation/test_stopping.py",
         "tests/estimation/test_feasible_descent.py", "tests/estimation/test_exact_hessian.py"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kernels", nargs="+", default=["default", "Haswell", "Zen", "Prescott"])
    parser.add_argument("--tests", nargs="+", default=TESTS)
    args = parser.parse_args()
    failed = 0
    for kernel in args.kernels:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel != "default":
            env["OPENBLAS_CORETYPE"] = kernel
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               *args.tests], env=env, cwd=ROOT, capture_output=True, text=True)
        summary = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
        print(f"{kernel:>10}: {summary}  ({time.perf_counter() - t0:.1f} s)", flush=True)
        failed += done.returncode != 0
    print("every kernel passed" if not failed else f"{failed} kernel(s) FAILED")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
