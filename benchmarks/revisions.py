"""Run benchmark code against the cpas_ocp of another git revision, in a child process.

Speed-ups are measured as ratios against the code they replace, run by the
same script on the same machine.  `code_at` checks a revision out in a
temporary worktree; `run_child` runs a script in a fresh Python process whose
``import cpas_ocp`` resolves to a given code tree (this tree's or a
worktree's), and returns the JSON object the script prints last; `call_at`
calls a function of a benchmark module so, with this tree's benchmark code
and the given tree's package; `compare_cases` does that for each case folder
with a revision's package and this tree's, alternately; `run_stage` runs a `cpas-ocp`
command with a given tree's package and times it, with its peak memory.

Paths the package no longer offers as switches are measured at the last
revision that had them: `SWITCHES` (Settings' `polish`, `damping` and
`descent_curvature`).
"""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import harness

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"

# The last revision whose Settings has the `polish`, `damping` and `descent_curvature`
# switches (each False: the path before the finishing steps, the Marquardt damping and
# the curvature-learning descent).
SWITCHES = "f73876d"

# Prepended to every child script: the project is installed in development mode,
# so its import mapping is pointed at the code tree given as the first argument.
PRELUDE = r"""
import sys
from pathlib import Path
code = Path(sys.argv[1])
for module in list(sys.modules.values()):
    if type(getattr(module, "MAPPING", None)) is dict and "cpas_ocp" in module.MAPPING:
        module.MAPPING.update({"cpas_ocp": str(code / "cpas_ocp"),
                               "cpas_ocp.problem_data": str(code / "problems"),
                               "cpas_ocp.schemas": str(code / "data_schemas")})
        module.NAMESPACES.update({"cpas_ocp": [str(code / "cpas_ocp")]})
sys.argv = sys.argv[1:]
"""


@contextlib.contextmanager
def code_at(revision: str | None) -> Iterator[Path]:
    """This tree (`revision` None) or a temporary worktree of `revision`."""
    if revision is None:
        yield ROOT
        return
    with tempfile.TemporaryDirectory() as tmp:
        worktree = Path(tmp) / "code"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(worktree),
                        revision], check=True, capture_output=True)
        try:
            yield worktree
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(worktree)], check=False, capture_output=True)


def run_child(script: str, code: Path, *args: str, cache: Path | None = None,
              compile_first: bool = False) -> Any:
    """Run `script` in a fresh process importing cpas_ocp from `code`; its last printed
    line, parsed as JSON.  `cache` is its compile cache (a new empty one when None);
    with `compile_first`, models compile before they run (CPAS_OCP_COMPILE=wait)."""
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "CPAS_OCP_CACHE": str(cache or scratch)}
        if compile_first:
            env["CPAS_OCP_COMPILE"] = "wait"
        out = subprocess.run([sys.executable, "-c", PRELUDE + script, str(code), *args],
                             env=env, cwd=scratch, capture_output=True, text=True, check=False)
    if out.returncode:
        raise RuntimeError(f"{' '.join(args)} with the code in {code} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


# Calls benchmarks/<module>.<function>(*args) and prints its JSON result.
CALL = r"""
import importlib, json, sys
sys.path.insert(0, sys.argv[1])
result = getattr(importlib.import_module(sys.argv[2]), sys.argv[3])(*json.loads(sys.argv[4]))
print(json.dumps(result))
"""


def call_at(code: Path, module: str, function: str, *args: object, cache: Path | None = None
            ) -> Any:
    """`function(*args)` of the benchmark `module`, run in a fresh process with this tree's
    benchmark code and the package from `code` (JSON arguments and result); its models
    compiled before they run (CPAS_OCP_COMPILE=wait), into `cache` where given, so that
    what is timed is native code on both sides."""
    return run_child(CALL, code, str(BENCHMARKS), module, function, json.dumps(args),
                     cache=cache, compile_first=True)


def compare_cases(benchmark: str, function: str, cases: Callable[[Path], dict[str, Path]],
                  against: str, describe: Callable[[dict[str, Any]], str],
                  repeat: int = 1) -> None:
    """Each case folder `cases` makes (in a temporary folder) given to `function` of the
    module `benchmark` with the package of `against` and with this tree's (`call_at`,
    after an untimed call with this tree's that compiles the models both use into one
    cache), the two alternately `repeat` times: a line per case, its name, what
    `describe` says of each side (its first call, with the median wall time) and the
    ratio of the median wall times now/`against`; then the benchmark's report
    (`harness.report`)."""
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, code_at(against) as before:
        cache = Path(tmp) / "cache"
        for name, folder in cases(Path(tmp)).items():
            call_at(ROOT, benchmark, function, str(folder), cache=cache)
            runs: dict[Path, list[dict[str, Any]]] = {before: [], ROOT: []}
            for _ in range(repeat):
                for code, made in runs.items():
                    made.append(call_at(code, benchmark, function, str(folder), cache=cache))
            old, new = ({**made[0], "wall_s": statistics.median(r["wall_s"] for r in made)}
                        for made in runs.values())
            rows[name] = harness.paired(old, new)
            print(f"{name:20s} {against}: {describe(old)} | now: {describe(new)} | ratio "
                  f"{harness.ratio_text(new['wall_s'], old['wall_s'])}", flush=True)
    harness.report(benchmark, against=against, cases=rows)


# A command of the code tree given first (`revisions.PRELUDE`), then its arguments.
COMMAND = "from cpas_ocp.cli import main; raise SystemExit(main(sys.argv[1:]))"


def run_stage(code: Path, args: list[str], cache: Path, timeout: float, cwd: Path) -> dict:
    """`cpas-ocp ARGS` with the package of `code` in a fresh process, stdout and stderr
    pipes: wall time (s), peak resident memory (MB, the process's ru_maxrss), exit code
    (None past `timeout`), the lines of stdout and the progress lines of stderr."""
    env = {**os.environ, "CPAS_OCP_CACHE": str(cache)}
    with tempfile.TemporaryFile(mode="w+") as out, tempfile.TemporaryFile(mode="w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", PRELUDE + COMMAND, str(code), *args],
                                env=env, cwd=cwd, stdout=out, stderr=err, text=True)
        code_, usage = None, None
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                code_ = os.waitstatus_to_exitcode(status)
                break
            if time.perf_counter() - t0 > timeout:
                proc.kill()
                _, _, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.2)
        wall = time.perf_counter() - t0
        proc.returncode = code_ if code_ is not None else -9
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    return {"wall_s": wall, "peak_mb": usage.ru_maxrss / 1024.0, "exit": code_,
            "stdout": stdout.splitlines(), "progress": [line for line in stderr.splitlines()
                                                        if line.startswith("  iteration")],
            "stderr_tail": stderr.splitlines()[-3:]}
