"""How long a command takes from the shell when it needs no estimator: `cpas-ocp --help`,
`cpas-ocp import --help`, and `cpas-ocp import` of a recorder's log, with the package of
revision REV (default `BEFORE`) and with this tree's.

At REV every command's parser imported the estimator (for the grid's finest step and
the covariance's curvatures) and `cpas_ocp.api` imported every workflow, with CasADi's
estimator, matplotlib and the campaign's study code among them; `import` printed its
summary through `api.summary`, which loads every report.  Now the parser reads its
limits from `estimation.fit` alone, the interface imports a workflow when it is first
used (PEP 562), and `import` reads a log without the estimator or matplotlib.

Each command runs as its own process (`python -m cpas_ocp.cli ...`, the interpreter's
start included), the two trees alternating, `--repeat` times; printed: the median wall
time of each and the ratio now/REV.  The logs: the suite's synthetic rocket flight in
its three recorder layouts (`tests/io/test_rocket_log_import.py`) and the two public
rocket logs in `../shared/data/rocketpy-logs` where present.

    python benchmarks/command_start.py [--against REV] [--repeat 5]
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import harness
from bounded_stop import LOGS, SHARED
from revisions import PRELUDE, ROOT, code_at

BEFORE = "937048b"

# The command line, run with the package of the code tree given first.
CLI = "import runpy; runpy.run_module('cpas_ocp.cli', run_name='__main__')"


def commands(root: Path) -> dict[str, list[str]]:
    """The commands timed, by name: the two help texts and one import per log (each
    layout's log and card written under `root`), an import's output folder left last."""
    sys.path.insert(0, str(ROOT))
    from tests.io import test_rocket_log_import as flights

    out = {"--help": ["--help"], "import --help": ["import", "--help"]}
    flight = flights.fly()
    for layout in ("altus", "cats", "columns"):
        folder = root / layout
        folder.mkdir()
        out[f"import, {layout}"] = [*flights.layout_arguments(layout, flight, folder), "--out"]
    for card, log in LOGS.items():
        if (SHARED / log).is_file():
            out[f"import, {card}"] = ["import", str(SHARED / log), "--card", card, "--out"]
    return out


def timed(code: Path, args: list[str], out: Path) -> float:
    """Wall seconds of one command with the package from `code` (`out` appended where its
    arguments end with ``--out``: a folder no other run writes)."""
    if args[-1] == "--out":
        args = [*args, str(out)]
    with tempfile.TemporaryDirectory() as scratch:
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", PRELUDE + CLI, str(code), *args],
                              cwd=scratch, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"{' '.join(args)} with the code in {code}: {done.stderr[-500:]}")
    return wall


def main() -> int:
    parser = harness.parser(__doc__, None)
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, code_at(args.against) as before:
        root = Path(tmp)
        for n, (name, command) in enumerate(commands(root).items()):
            walls: dict[str, list[float]] = {"before": [], "now": []}
            for k in range(args.repeat):
                for side, code in (("before", before), ("now", ROOT)):
                    walls[side].append(timed(code, command, root / f"out-{n}-{side}-{k}"))
            old, new = (statistics.median(walls[s]) for s in ("before", "now"))
            rows[name] = {"before_s": old, "now_s": new, "wall_ratio": harness.ratio(new, old)}
            print(f"{name:24s} {args.against}: {old:5.2f} s | now: {new:5.2f} s | ratio "
                  f"{harness.ratio_text(new, old)}", flush=True)
    harness.report("command_start", against=args.against, cases=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
