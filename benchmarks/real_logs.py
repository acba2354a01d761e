"""Benchmark: the public rocket logs imported as published and reconstructed, as a rocketry
user would run them, and what each run says happened on the flight.

Each log of `../shared/data/rocketpy-logs/` (PROVENANCE.md there) runs `cpas-ocp import LOG
--card CARD` with its built-in card (`problems/*.json`, written from docs/flight-card.md),
then `cpas-ocp reconstruct`, each command a fresh process on one compile cache (the first
log compiles what the later ones reuse).  Recorded per log: what the import's deployment
forensics say of each canopy (its verdict and sentence), the reconstruction's exit code (0
a result, 4 a fit that is not one) and claim, its chi-square/dof, each canopy's drag area
with its sigma, and the wall time and peak memory of both commands.  Exits 2 where the
shared folder is absent.

    python benchmarks/real_logs.py [--logs ndrt_2020 genesis_2023 ...] [--timeout S]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import harness  # noqa: E402
from benchmarks.revisions import run_stage  # noqa: E402
from tests.io.test_rocketpy_logs import DATA, LOGS  # noqa: E402


def run_log(card: str, work: Path, cache: Path, timeout: float) -> dict:
    """Import and reconstruct one log; what each command said and cost."""
    imported = run_stage(ROOT, ["import", str(DATA / LOGS[card]), "--card", card,
                                "--out", str(work / "test")], cache, timeout, work)
    row = {"log": card, "import_exit": imported["exit"], "import_s": imported["wall_s"]}
    summary = work / "test" / "import.json"
    if summary.is_file():
        deployments = json.loads(summary.read_text()).get("deployments", {})
        row["import_says"] = "; ".join(f"{name}: {d['sentence']}"
                                       for name, d in deployments.items())
    if imported["exit"] != 0:
        return row | {"stderr": " ".join(imported["stderr_tail"])}
    fitted = run_stage(ROOT, ["reconstruct", str(work / "test"), "--out",
                              str(work / "report")], cache, timeout, work)
    row |= {"exit": fitted["exit"], "reconstruct_s": fitted["wall_s"],
            "peak_mb": max(imported["peak_mb"], fitted["peak_mb"])}
    result = work / "report" / "result.json"
    if not result.is_file():
        return row | {"stderr": " ".join(fitted["stderr_tail"])}
    res = json.loads(result.read_text())
    claim = res["claim"]
    row |= {"verdict": claim["verdict"], "chi2_dof": res["fit"]["chi_square_per_dof"],
            "iterations": res["solver"]["iterations"],
            "drag_areas_m2": harness.estimates_text(
                (k, v["value"], v.get("std")) for k, v in res["parameters"].items()
                if k.startswith("CdS")),
            "claim_leads_with": (claim.get("problems") or [""])[0]}
    return row


def main() -> int:
    parser = harness.parser(__doc__, seed=None, seed_help="recorded only: nothing is drawn")
    parser.add_argument("--logs", nargs="+", default=sorted(LOGS), choices=sorted(LOGS),
                        help="the built-in cards of the logs to run (default: all)")
    parser.add_argument("--timeout", type=float, default=900.0,
                        help="stop a command after this many seconds (default 900)")
    args = parser.parse_args()
    if not (DATA / "rocketpy-logs").is_dir():
        print(f"real_logs: {DATA / 'rocketpy-logs'}: the folder of public logs is absent",
              file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-real-logs-") as tmp:
        for card in args.logs:
            work = Path(tmp) / card
            work.mkdir()
            row = run_log(card, work, Path(tmp) / "cache", args.timeout)
            rows.append(row)
            print(json.dumps(row), flush=True)
    harness.report("real_logs", logs=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
