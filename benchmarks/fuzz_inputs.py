"""Long profile of the property-based input tests: many corrupted manifests, series, model
files, flight cards, Altus Metrum logs, column maps, CATS exports, flight cards for
`flight`, campaign tables, scheduler addresses, and plug-ins that fail.

Runs `tests/io/test_fuzz_manifest.py`, `tests/io/test_fuzz_files.py`,
`tests/cli/test_plugin_faults.py` and `tests/io/test_fuzz_logs.py` (its slow
campaign-table test too) with `--examples` examples of each kind
(default 2,000) drawn from `--seed` (the suite runs 30 fixed ones).  Every example must be
valid input or a one-line exit 2 with nothing written; a failure prints
Hypothesis's smallest falsifying example.  Prints the count and the wall time.

    python benchmarks/fuzz_inputs.py [--examples 2000] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    env = {**os.environ, "CPAS_OCP_FUZZ_EXAMPLES": str(args.examples),
           "CPAS_OCP_FUZZ_SEED": str(args.seed)}
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           f"--hypothesis-seed={args.seed}",
                           str(ROOT / "tests" / "test_fuzz_manifest.py"),
                           str(ROOT / "tests" / "test_fuzz_files.py"),
                           str(ROOT / "tests" / "test_plugin_faults.py"),
                           str(ROOT / "tests" / "test_fuzz_logs.py")], env=env, cwd=ROOT)
    verdict = "contract held" if done.returncode == 0 else "FAILED"
    print(f"{args.examples} each of corrupted manifests, series, model files, flight cards, "
          f"Altus Metrum logs, column maps, CATS exports, campaign tables, scheduler "
          f"addresses and failing plug-ins (seed {args.seed}) in "
          f"{time.perf_counter() - t0:.1f} s: {verdict}")
    return done.returncode


if __name__ == "__main__":
    sys.exit(main())
