"""Benchmark: campaign throughput on 1 and 2 local worker processes, in the same process.

Simulates N FBCP test folders (seeds 1..N; from `--seed` on), reconstructs them with
`run_campaign` on one worker and then on two, and prints the wall times, tests per minute
and the speed-up.
`python benchmarks/campaign_throughput.py [--tests 8] [--seed 1]`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness

from cpas_ocp.campaign.campaign import run_campaign
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem


def main() -> None:
    ap = harness.parser(__doc__, seed=1, seed_help="the first test's seed")
    ap.add_argument("--tests", type=int, default=8)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folders = []
        for seed in range(args.seed, args.seed + args.tests):
            folder = Path(tmp) / f"fbcp{seed}"
            simulate_problem(load_problem("fbcp"), folder, seed)
            (folder / "truth.json").unlink()
            folders.append(folder)
        run_campaign(folders[:1], workers=1)  # compiled model functions built once, not timed
        timer = harness.Timer()
        failed = {}
        for workers in (1, 2):
            with timer(str(workers)):
                outcomes = run_campaign(folders, workers=workers)
            wall, failed[workers] = timer[str(workers)], sum(not o.ok for o in outcomes)
            print(f"{workers} worker(s): {wall:.1f} s, "
                  f"{60 * args.tests / wall:.1f} tests per minute, {failed[workers]} failed")
    speed_up = harness.ratio(timer["1"], timer["2"])
    print(f"speed-up with 2 workers: {speed_up:.2f}")
    harness.report("campaign_throughput", tests=args.tests, wall_s={1: timer["1"], 2: timer["2"]},
                   failed=failed, speed_up=speed_up)


if __name__ == "__main__":
    main()
