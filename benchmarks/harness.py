"""What every benchmark script shares: its command line, timer, ratios and last line.

    args = harness.parser(__doc__, seed=1).parse_args()
    timer = harness.Timer()
    with timer("solve"):
        fit = est.solve()
    harness.report("NAME", solve_s=timer["solve"], speed_up=harness.ratio(old_s, new_s))

Scripts run as ``python benchmarks/NAME.py`` and import this file as a sibling.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

# what the last parse_args read; a script that never parses records its result
_RUN: dict[str, Any] = {"seed": None, "json": None, "record": True}


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser that keeps --seed and --json for `report`."""

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None
                         ) -> tuple[argparse.Namespace, list[str]]:
        ns, rest = super().parse_known_args(args, namespace)
        _RUN.update(seed=getattr(ns, "seed", None), json=getattr(ns, "json", None),
                    record=not getattr(ns, "no_record", False))
        return ns, rest


def parser(doc: str | None, seed: int | None, seed_help: str = "seed of the random draws"
           ) -> argparse.ArgumentParser:
    """The script's parser: `doc`'s first paragraph as description, ``--seed`` (default
    `seed`; None where the script draws nothing of its own, or its draws are seeded by its
    other options, and the seed is only recorded), ``--json PATH`` and ``--no-record``."""
    ap = _Parser(description=(doc or "").strip().split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=seed,
                    help=seed_help if seed is None else f"{seed_help} (default {seed})")
    ap.add_argument("--json", type=Path, default=None, metavar="PATH",
                    help="also append the result line (JSON) to this file")
    ap.add_argument("--no-record", action="store_true",
                    help="do not write the result as the benchmark's latest "
                    "(benchmarks/results/NAME.json, rendered into the documentation site)")
    return ap


class Timer:
    """Wall-clock seconds (`time.perf_counter`) per label.

    ``with timer("build"): ...`` times a block (a block that raises is timed too);
    ``timer["build"]`` is its last time, ``timer.laps["build"]`` every time in order;
    ``timer.elapsed()`` the seconds since the timer was made; ``timer.split("step")``
    records the seconds since the previous split (or since the timer was made).
    """

    def __init__(self) -> None:
        self.laps: dict[str, list[float]] = {}
        self._start = self._mark = time.perf_counter()

    @contextlib.contextmanager
    def __call__(self, label: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.laps.setdefault(label, []).append(time.perf_counter() - t0)

    def __getitem__(self, label: str) -> float:
        return self.laps[label][-1]

    def seconds(self) -> dict[str, float]:
        """Each label's last time."""
        return {label: laps[-1] for label, laps in self.laps.items()}

    def elapsed(self) -> float:
        """Seconds since the timer was made."""
        return time.perf_counter() - self._start

    def split(self, label: str) -> float:
        """Record and return the seconds since the previous split (or the timer's start)."""
        now = time.perf_counter()
        self.laps.setdefault(label, []).append(now - self._mark)
        self._mark = now
        return self.laps[label][-1]


def ratio(new: float, old: float) -> float:
    """``new / old``: two figures of one run, the first over the second (a new path's time
    over the old one's; a speed-up is old time over new); NaN where `old` is zero or either
    is not finite."""
    new, old = float(new), float(old)
    if old == 0.0 or not (math.isfinite(new) and math.isfinite(old)):
        return math.nan
    return new / old


def paired(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """One case's results at two revisions, each with its ``wall_s``: both, and the ratio of
    wall times new/old."""
    return {"before": old, "now": new, "wall_ratio": ratio(new["wall_s"], old["wall_s"])}


def ratio_text(new: float, old: float, spec: str = ".2f") -> str:
    """`ratio` formatted with the format `spec` (``nan`` where it is undefined)."""
    return format(ratio(new, old), spec)


def _plain(value: Any) -> Any:
    """`value` as JSON: numbers, strings, lists and objects; NaN and inf as None."""
    if hasattr(value, "tolist") and not isinstance(value, str):  # numpy arrays and scalars
        value = value.tolist()
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):  # keys as text; a tuple's items joined by commas
        return {",".join(map(str, k)) if isinstance(k, tuple) else str(k): _plain(v)
                for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v) for v in value]
    return str(value)


def table(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> dict[str, Any]:
    """A result that is a table: its `columns` and `rows` (a row per case, a value per
    column).  `report` records it as ``{"columns": ..., "rows": ...}``, and the documentation
    site renders it as a table where docs/validation.md names the benchmark."""
    if any(len(row) != len(columns) for row in rows):
        raise ValueError(f"a table of {len(columns)} columns given a row of another length")
    return {"columns": list(columns), "rows": [list(row) for row in rows]}


def estimates_text(estimates: Iterable[tuple[str, float, float | None]]) -> str:
    """``name value ± sigma, ...``: each estimate to its sigma's precision, as the reports
    print it (`cpas_ocp.precision.with_sigma`), for a record's table cell."""
    from cpas_ocp.precision import with_sigma

    return ", ".join(f"{name} {with_sigma(value, sigma)}" for name, value, sigma in estimates)


RESULTS = Path(__file__).resolve().parent / "results"  # each benchmark's latest result


def revision() -> str:
    """The source revision the benchmark ran (git's abbreviated commit, "+changes" where the
    tree differed from it; "unknown" outside a git checkout)."""
    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=root,
                                capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("+changes" if dirty.strip() else "")


def machine() -> dict[str, Any]:
    """What the figures were measured on: CPUs, platform, Python and CasADi versions."""
    import casadi

    return {"cpus": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), "casadi": casadi.__version__}


def report(name: str, **results: Any) -> dict[str, Any]:
    """Print the benchmark's result line, ``JSON: {...}``, write it as the benchmark's latest
    result (``benchmarks/results/<name>.json``, which the documentation site's validation
    tables are rendered from; not with ``--no-record``), and append it to --json where
    given: the benchmark's `name`, its seed, the revision, the date (UTC), the machine, the
    load average, the command line and `results`.  Call it last; it returns what it
    wrote."""
    line = {"benchmark": name, "seed": _RUN["seed"], "revision": revision(),
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": machine(), "load_average": list(os.getloadavg()),
            "cpus": os.cpu_count(), "command": " ".join(sys.argv),
            "results": _plain(results)}
    text = json.dumps(line, allow_nan=False)
    print(f"JSON: {text}", flush=True)
    if _RUN["record"]:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / f"{name}.json").write_text(json.dumps(line, indent=1, allow_nan=False)
                                              + "\n")
    if _RUN["json"] is not None:
        path = Path(_RUN["json"])
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a") as fh:
            fh.write(text + "\n")
    return line


def seeds_parser(doc: str | None, seeds: int) -> argparse.ArgumentParser:
    """`parser` for a script scored over seeds: ``--seeds`` (default `seeds`), ``--first``
    and ``--workers``; each seed's draws are seeded by the seed itself."""
    ap = parser(doc, seed=None, seed_help="recorded only: each seed's draws are seeded by "
                "that seed (--first, --seeds)")
    ap.add_argument("--seeds", type=int, default=seeds)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    return ap


def run_seeds(run: Callable[[int], dict[str, Any]], args: argparse.Namespace,
              out: Path | None = None) -> list[dict[str, Any]]:
    """`run(seed)` for each seed of `args` (`seeds_parser`) on `args.workers` processes, in
    order; each row printed as JSON as it comes, and appended to `out` where given."""
    from concurrent.futures import ProcessPoolExecutor
    seeds = list(range(args.first, args.first + args.seeds))
    rows = []
    with ProcessPoolExecutor(args.workers) as pool:
        for row in pool.map(run, seeds):
            rows.append(row)
            print(json.dumps(row), flush=True)
            if out is not None:
                with out.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
    return rows

