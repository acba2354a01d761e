"""Benchmark: the demo's output before and after a change of layout is the same.

Runs `cpas-ocp demo` (seed 1) from a worktree of an earlier revision (default:
the last commit before the subpackages, fd95edf) and from the working tree,
each in its own process, and compares:

* the printed output, line by line (timings and folder paths masked);
* result.json: every number but wall-clock times to a relative 1e-9 (the same arithmetic gives the
  same bits; a re-ordered sum may move the last digit);
* parameters.csv, cell by cell, likewise;
* every figure, pixel by pixel (PNG metadata ignored).

    python benchmarks/layout_unchanged.py [--rev REV]

Each side is imported from its own source tree, with this checkout's editable
install taken off the import path and the package data (problems, schemas)
registered from that tree, so each side runs its own code and data.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import harness
import matplotlib.image as mpimg
import numpy as np
import pandas as pd
from revisions import ROOT, code_at

RUN = """
import importlib.util, sys
sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
sys.path[:] = [{src!r}] + [p for p in sys.path if p and "editable" not in p.lower()]
for name, folder in (("cpas_ocp.problem_data", "problems"), ("cpas_ocp.schemas", "data_schemas")):
    spec = importlib.util.spec_from_file_location(
        name, {src!r} + "/" + folder + "/__init__.py",
        submodule_search_locations=[{src!r} + "/" + folder])
    sys.modules[name] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sys.modules[name])
import cpas_ocp.cli
assert cpas_ocp.cli.__file__.startswith({src!r}), cpas_ocp.cli.__file__
from cpas_ocp.cli import main
sys.exit(main(["demo", "--out", {out!r}]))
"""
TIMINGS = {"wall_s"}  # result.json keys that hold wall-clock times
MASKS = (re.compile(r"\d+(\.\d+)? ?(s|ms|min)\b"), re.compile(r"/tmp/\S+"))


def demo(src: Path, out: Path) -> list[str]:
    """Run the demo with the code under `src` into `out`; its printed lines, masked."""
    done = subprocess.run([sys.executable, "-c", RUN.format(src=str(src), out=str(out))],
                          capture_output=True, text=True, check=False, cwd=out.parent)
    if done.returncode != 0:
        raise SystemExit(f"the demo from {src} failed:\n{done.stderr}")
    lines = done.stdout.splitlines()
    for mask in MASKS:
        lines = [mask.sub("#", line) for line in lines]
    return lines


def numbers_differ(a: object, b: object, path: str = "") -> list[str]:
    """Where two JSON values differ (numbers beyond a relative 1e-9)."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = sorted((set(a) | set(b)) - TIMINGS)
        return [d for k in keys for d in numbers_differ(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in numbers_differ(x, y, f"{path}[{i}]")]
    if isinstance(a, float | int) and isinstance(b, float | int):
        return [] if math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) else [f"{path}: {a} != {b}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def main() -> None:
    parser = harness.parser(__doc__, seed=None,
                            seed_help="recorded only: the demo draws with its own seed (1)")
    parser.add_argument("--rev", default="fd95edf")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        with code_at(args.rev) as old_src:
            printed = [demo(old_src, tmp / "before"), demo(ROOT, tmp / "after")]
        before, after = tmp / "before" / "report", tmp / "after" / "report"
        diffs = [f"printed line {i}: {x!r} != {y!r}"
                 for i, (x, y) in enumerate(zip(*printed, strict=False)) if x != y]
        if len(printed[0]) != len(printed[1]):
            diffs.append(f"printed {len(printed[0])} lines before, {len(printed[1])} after")
        diffs += numbers_differ(json.loads((before / "result.json").read_text()),
                                json.loads((after / "result.json").read_text()), "result")
        a = pd.read_csv(before / "parameters.csv")
        b = pd.read_csv(after / "parameters.csv")
        if a.shape != b.shape or list(a.columns) != list(b.columns):
            diffs.append("parameters.csv: shape or columns differ")
        else:
            for col in a.columns:
                if pd.api.types.is_numeric_dtype(a[col]):
                    if not np.allclose(a[col], b[col], rtol=1e-9, atol=1e-12, equal_nan=True):
                        diffs.append(f"parameters.csv column {col} differs")
                elif not a[col].equals(b[col]):
                    diffs.append(f"parameters.csv column {col} differs")
        figures = sorted(p.name for p in before.glob("*.png"))
        if figures != sorted(p.name for p in after.glob("*.png")):
            diffs.append("the figures' names differ")
        for name in figures:
            x, y = mpimg.imread(before / name), mpimg.imread(after / name)
            if x.shape != y.shape or not np.array_equal(x, y):
                diffs.append(f"figure {name} differs")
        print(f"compared {len(printed[1])} printed lines, result.json, parameters.csv and "
              f"{len(figures)} figures ({', '.join(figures)}) of {args.rev} and the working "
              "tree")
        print("identical" if not diffs else "DIFFERENT:\n" + "\n".join(diffs))
        harness.report("layout_unchanged", rev=args.rev, printed_lines=len(printed[1]),
                       figures=figures, identical=not diffs, differences=diffs)
        sys.exit(1 if diffs else 0)


if __name__ == "__main__":
    main()
