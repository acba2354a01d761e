"""An interrupt while native code compiles: Ctrl-C or SIGTERM while the C compiler builds a
model's functions (a compiler script made slow on purpose) ends the command with exit 130
or 143, one line, no compiler process left running and no output folder; a campaign's
workers leave none either.  The suite's smaller cases: `tests/test_interrupts.py` (a signal
mid-solve, while the arguments are parsed, in the first moments of the command line)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.test_interrupts import _interrupted


def _processes() -> dict[int, tuple[int, str, str]]:
    """Every process: its parent, name and state (read from /proc)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # ended meanwhile
            continue
        name = text[text.index("(") + 1:text.rindex(")")]
        state, ppid = text[text.rindex(")") + 2:].split()[:2]
        out[int(stat.parent.name)] = (int(ppid), name, state)
    return out


def _descendants(pid: int) -> dict[int, str]:
    """The processes below `pid`, by id, with their names."""
    table = _processes()
    found: dict[int, str] = {}
    todo = [pid]
    while todo:
        parent = todo.pop()
        for child, (ppid, name, _) in table.items():
            if ppid == parent and child not in found:
                found[child] = name
                todo.append(child)
    return found


def _running(pid: int) -> bool:
    """Whether `pid` still runs (a zombie, awaiting its reaper, does not)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return text[text.rindex(")") + 2] != "Z"


# A C compiler whose pass (a `sleep`, as gcc's cc1) outlives a driver killed alone.
SLOW_COMPILER = """#!/bin/sh
sleep 60 &
wait
"""


def _interrupted_while_compiling(command: list[str], sig: int, tmp_path: Path,
                                 compilers: int = 1, mode: str = "1") -> None:
    """Run the command line's `command` with a fresh compile cache and a stand-in compiler
    (`mode`: CPAS_OCP_COMPILE, compiling in the background or first); once `compilers` of
    them run, send `sig`: the command ends interrupted, none of the compilers' processes
    survive, and no temporary folder is left."""
    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "gcc").write_text(SLOW_COMPILER)
    (tmp_path / "bin" / "gcc").chmod(0o755)
    cache = tmp_path / "cache"
    proc = subprocess.Popen([sys.executable, "-m", "cpas_ocp.cli", *command],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "CPAS_OCP_CACHE": str(cache),
                                 "CPAS_OCP_COMPILE": mode,
                                 "PATH": f"{tmp_path / 'bin'}{os.pathsep}{os.environ['PATH']}"})
    below: dict[int, str] = {}
    while proc.poll() is None and list(below.values()).count("sleep") < compilers:
        time.sleep(0.02)
        below = _descendants(proc.pid)
    assert proc.poll() is None, "the command ended before it compiled"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    _interrupted(err, sig + 128, proc.returncode)
    time.sleep(0.2)  # SIGKILL is delivered at once, but a process takes a moment to end
    assert not [name for pid, name in below.items() if _running(pid)]
    assert not list(cache.glob(".cpas-cg-*")) and not list(tmp_path.glob("**/.cpas-*"))


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_while_compiling_leaves_no_compiler_and_no_folder(sig, problem_folder,
                                                                       tmp_path) -> None:
    """Interrupted while the model compiles in the background (a fresh cache; a diagnosis,
    whose second estimator starts the compilers), the command kills each compiler with the
    passes it started (gcc's cc1 and as; here a stand-in's `sleep`), and leaves no temporary
    folder.  On `fbcp`, whose first fit in the VM is the shortest of the problems'."""
    _interrupted_while_compiling(["diagnose", str(problem_folder("fbcp", 1)), "--out",
                                  str(tmp_path / "diagnosis")], sig, tmp_path)
    assert not (tmp_path / "diagnosis").exists()


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_an_interrupt_while_waiting_for_the_compiler_ends_the_build(tmp_path) -> None:
    """Compiling first (CPAS_OCP_COMPILE=wait), a signal that arrives while the estimator's
    build waits for its compilers ends the wait: the compilers are killed, the build ends
    and the command is interrupted, not held until the compilers finish."""
    _interrupted_while_compiling(["demo", "--out", str(tmp_path / "demo")], signal.SIGINT,
                                 tmp_path, mode="wait")
    assert not list((tmp_path / "demo").glob("*"))


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_an_interrupted_campaign_leaves_no_compiler_of_its_workers(drogue_folder,
                                                                   tmp_path) -> None:
    """A campaign's local workers, ended by the command, kill the compilers they started
    (in process groups of their own, which the workers' death would not reach)."""
    for seed in (1, 2):
        shutil.copytree(drogue_folder(seed), tmp_path / "tests" / f"drogue{seed}")
    _interrupted_while_compiling(["campaign", str(tmp_path / "tests"), "--out",
                                  str(tmp_path / "campaign"), "--workers", "2"],
                                 signal.SIGINT, tmp_path, compilers=2, mode="wait")
    assert not (tmp_path / "campaign").exists()
