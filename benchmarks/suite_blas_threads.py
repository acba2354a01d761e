"""Test files run as the suite runs them (`-n 2 --dist loadfile`), each worker's BLAS on
a pool of threads as many as the cores against one holding its share of them.

OpenBLAS starts a pool of one thread per core in every process that loads it (NumPy's,
SciPy's and CasADi's copies alike), and a pool's threads wait for work by spinning.
Two pytest workers on two cores, each with such a pool, contend for the cores in every
dense product of the estimator's linear algebra (`kkt_system`: the reduced problem's
products and eigen-decompositions).  `tests/conftest.py` gives each worker its share of
the cores (one thread of two, here) unless ``OPENBLAS_NUM_THREADS`` or
``OMP_NUM_THREADS`` is set; the baseline sets both to the core count, the pools as they
were.

Each side runs the files `--repeat` times, alternating, with one compile cache warmed by
a first run of each side beforehand (so that both run the same native code).  Printed:
each run's wall time and the CPU seconds of its processes (user and system), the median
of each side, and the ratios share/full.

    python benchmarks/suite_blas_threads.py [--repeat 2] [FILE ...]
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import harness
from revisions import ROOT

# The files that reach the linear algebra most, among the longest of the suite.
FILES = ("tests/estimation/test_nlp_functions.py", "tests/inference/test_result_claim.py",
         "tests/discrepancy/test_verdicts.py", "tests/inference/test_claim_limits.py")
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def run(files: list[str], cache: Path, full_pools: bool) -> tuple[float, float]:
    """Wall and CPU seconds of one run of `files` with two workers: each worker's BLAS pool
    as many threads as the cores (`full_pools`), else the suite's default."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env["CPAS_OCP_CACHE"] = str(cache)
    if full_pools:
        env.update({k: str(os.cpu_count() or 1) for k in THREAD_VARIABLES})
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist",
                           "loadfile", "-p", "no:cacheprovider", *files], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise RuntimeError(f"the tests failed ({'full' if full_pools else 'share'}): "
                           f"{done.stdout[-800:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> int:
    parser = harness.parser(__doc__, None)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("files", nargs="*", default=list(FILES))
    args = parser.parse_args()
    sides = {"full": True, "share": False}
    laps: dict[str, list[tuple[float, float]]] = {side: [] for side in sides}
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp)
        for full in sides.values():  # warm the compile cache for both sides
            run(args.files, cache, full)
        for k in range(args.repeat):
            for side, full in sides.items():
                wall, cpu = run(args.files, cache, full)
                laps[side].append((wall, cpu))
                print(f"run {k + 1} {side:5s}: {wall:7.1f} s wall, {cpu:7.1f} CPU-s", flush=True)
    wall = {side: statistics.median(w for w, _ in runs) for side, runs in laps.items()}
    cpu = {side: statistics.median(c for _, c in runs) for side, runs in laps.items()}
    print(f"median wall: full pools {wall['full']:.1f} s, share {wall['share']:.1f} s, "
          f"ratio {harness.ratio_text(wall['share'], wall['full'])}")
    print(f"median CPU:  full pools {cpu['full']:.1f} s, share {cpu['share']:.1f} s, "
          f"ratio {harness.ratio_text(cpu['share'], cpu['full'])}")
    harness.report("suite_blas_threads", files=args.files, cores=os.cpu_count(),
                   wall_s=wall, cpu_s=cpu, wall_ratio=harness.ratio(wall["share"], wall["full"]),
                   cpu_ratio=harness.ratio(cpu["share"], cpu["full"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
