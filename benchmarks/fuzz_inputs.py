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

import os
import subprocess
import sys
from pathlib import Path

import harness

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = harness.parser(__doc__, seed=0, seed_help="Hypothesis's seed")
    parser.add_argument("--examples", type=int, default=2000)
    args = parser.parse_args()
    env = {**os.environ, "CPAS_OCP_FUZZ_EXAMPLES": str(args.examples),
           "CPAS_OCP_FUZZ_SEED": str(args.seed)}
    timer = harness.Timer()
    with timer("pytest"):
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               f"--hypothesis-seed={args.seed}",
                               str(ROOT / "tests" / "io" / "test_fuzz_manifest.py"),
                               str(ROOT / "tests" / "io" / "test_fuzz_files.py"),
                               str(ROOT / "tests" / "cli" / "test_plugin_faults.py"),
                               str(ROOT / "tests" / "io" / "test_fuzz_logs.py")],
                              env=env, cwd=ROOT)
    verdict = "contract held" if done.returncode == 0 else "FAILED"
    print(f"{args.examples} each of corrupted manifests, series, model files, flight cards, "
          f"Altus Metrum logs, column maps, CATS exports, campaign tables, scheduler "
          f"addresses and failing plug-ins (seed {args.seed}) in "
          f"{timer['pytest']:.1f} s: {verdict}")
    harness.report("fuzz_inputs", examples=args.examples, verdict=verdict,
                   exit_code=done.returncode, wall_s=timer["pytest"])
    return done.returncode


if __name__ == "__main__":
    sys.exit(main())
