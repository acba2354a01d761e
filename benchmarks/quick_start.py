"""How long the README's two Quick-start commands take once installed: `cpas-ocp demo` (the
built-in `drogue` test simulated, reconstructed and reported) and the suite
(`python -m pytest -q -n 2 --dist loadfile`, the README's check of these times left out),
each as its own process from the shell.

The README states both figures as one line each; `tests/docs/test_readme.py` checks that
what it states agrees with this script's latest recorded result
(`benchmarks/results/quick_start.json`), so a README that drifts from the measurement
fails the suite.  The suite's run is long (minutes on 2 cores): `--no-suite`
times the demo alone and keeps the suite's figures of the previous record.

    python benchmarks/quick_start.py [--repeat 3] [--no-suite]
"""

from __future__ import annotations

import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import harness

ROOT = Path(__file__).resolve().parents[1]
# The README's test command; the check of the README's times is left out of the run that
# measures them (it reads the record this run is about to write).
TIMES_CHECK = "tests/docs/test_readme.py::test_the_stated_times_are_the_latest_measured"
SUITE = [sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile",
         "-p", "no:cacheprovider", "--deselect", TIMES_CHECK]


def demo_seconds(repeat: int) -> list[float]:
    """Wall seconds of `cpas-ocp demo`, `repeat` times, each in a fresh folder (no compiled
    functions or results from an earlier run, apart from CasADi's cache of compiled code,
    which a user's second run keeps too)."""
    walls = []
    for k in range(repeat):
        with tempfile.TemporaryDirectory(prefix="cpas-quick-start-") as work:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "cpas_ocp.cli", "demo"], cwd=work,
                           check=True, capture_output=True, text=True)
            walls.append(time.perf_counter() - t0)
        print(f"demo run {k + 1}: {walls[-1]:.1f} s", flush=True)
    return walls


def suite_run() -> dict[str, float | int]:
    """The suite as the README runs it: its wall seconds and how many tests passed,
    failed, were skipped or expected to fail."""
    t0 = time.perf_counter()
    done = subprocess.run(SUITE, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    last = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    counts = {kind: int(n) for n, kind in re.findall(r"(\d+) (passed|failed|skipped|"
                                                     r"xfailed|xpassed|error)", last)}
    print(f"suite: {wall:.0f} s; {last}", flush=True)
    return {"wall_s": wall, "exit_code": done.returncode, **counts}


def main() -> int:
    ap = harness.parser(__doc__, seed=None)
    ap.add_argument("--repeat", type=int, default=3, help="demo runs (default 3)")
    ap.add_argument("--no-suite", action="store_true",
                    help="time the demo alone; the suite's figures are the last record's")
    args = ap.parse_args()
    walls = demo_seconds(args.repeat)
    if args.no_suite:
        previous = harness.RESULTS / "quick_start.json"
        suite = json.loads(previous.read_text())["results"]["suite"] if previous.is_file() \
            else None
    else:
        suite = suite_run()
    harness.report("quick_start", demo={"median_s": statistics.median(walls), "runs_s": walls},
                   suite=suite)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
