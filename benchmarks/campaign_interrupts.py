"""A signal to a campaign mid-run, repeated: do the worker processes end with the command?

Each trial runs `cpas-ocp campaign` on three copies of a simulated `fbcp` folder
(seed 1 unless `--seed`) with two workers whose every task announces itself and then
pauses for ten minutes, sends SIGINT to the process group (as a terminal's Ctrl-C does) or
SIGTERM to the command alone once both workers have started, and records
how it ended: the exit code, whether every worker was gone within 30 s, and
whether the command hung (no exit within 120 s) or ended before its workers
started.  Trials may run concurrently (`--parallel`) to load the machine.

    python benchmarks/campaign_interrupts.py [--trials 6] [--parallel 2] [--seed 1]
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import harness
import psutil

from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem

CAMPAIGN = """
import sys, time
import cpas_ocp.campaign.campaign as campaign
def paused(folder):
    print("task", flush=True)
    time.sleep(600.0)
campaign.reconstruct_folder = paused
from cpas_ocp.cli import main
sys.exit(main(sys.argv[1:]))
"""


def trial(folder: Path, root: Path, sig: signal.Signals) -> str:
    tests = root / "tests"
    for k in range(3):
        shutil.copytree(folder, tests / f"fbcp{k}")
    proc = subprocess.Popen([sys.executable, "-u", "-c", CAMPAIGN, "campaign", str(tests),
                             "--out", str(root / "out"), "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    started = 0
    assert proc.stdout is not None
    for line in proc.stdout:
        started += line.startswith("task")
        if started == 2:
            break
    if started < 2:
        _, err = proc.communicate(timeout=60)
        return f"ended before its workers started (exit {proc.returncode}): {err.strip()[-200:]}"
    workers = psutil.Process(proc.pid).children(recursive=True)
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    try:
        proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        return "HUNG (no exit within 120 s)"
    _, alive = psutil.wait_procs(workers, timeout=30.0)
    left = (root / "out").exists() or any(root.glob(".cpas-out-*"))
    return (f"exit {proc.returncode}, {len(workers)} workers, {len(alive)} left alive"
            f"{', output left behind' if left else ''}")


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated fbcp test")
    parser.add_argument("--trials", type=int, default=6)
    parser.add_argument("--parallel", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "fbcp"
        simulate_problem(load_problem("fbcp"), folder, args.seed)
        signals = [signal.SIGINT if k % 2 == 0 else signal.SIGTERM for k in range(args.trials)]
        with ThreadPoolExecutor(args.parallel) as pool:
            results = pool.map(lambda k: trial(folder, Path(tmp) / f"t{k}", signals[k]),
                               range(args.trials))
            outcomes = []
            for k, result in enumerate(results):
                print(f"trial {k + 1} ({signals[k].name}): {result}", flush=True)
                outcomes.append({"signal": signals[k].name, "outcome": result})
    harness.report("campaign_interrupts", trials=outcomes,
                   hung=sum(o["outcome"].startswith("HUNG") for o in outcomes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
