"""Benchmark: campaign throughput on 1 and 2 local worker processes, in the same process.

Simulates N FBCP test folders (seeds 1..N), reconstructs them with `run_campaign` on one
worker and then on two, and prints the wall times, tests per minute and the speed-up.
`python benchmarks/campaign_throughput.py [--tests 8]`.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from cpas_ocp.campaign.campaign import run_campaign
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tests", type=int, default=8)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folders = []
        for seed in range(1, args.tests + 1):
            folder = Path(tmp) / f"fbcp{seed}"
            simulate_problem(load_problem("fbcp"), folder, seed)
            (folder / "truth.json").unlink()
            folders.append(folder)
        run_campaign(folders[:1], workers=1)  # compiled model functions built once, not timed
        times = {}
        for workers in (1, 2):
            t0 = time.perf_counter()
            outcomes = run_campaign(folders, workers=workers)
            times[workers] = time.perf_counter() - t0
            failed = sum(not o.ok for o in outcomes)
            print(f"{workers} worker(s): {times[workers]:.1f} s, "
                  f"{60 * args.tests / times[workers]:.1f} tests per minute, {failed} failed")
    print(f"speed-up with 2 workers: {times[1] / times[2]:.2f}")


if __name__ == "__main__":
    main()
