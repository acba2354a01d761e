"""Ctrl-C and SIGTERM end a command in order: exit 130 or 143, one line, nothing left behind."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

# The command, with Ipopt's first iteration callback announcing itself and then pausing, so
# that the signal surely arrives inside the solver whatever the machine's load.
RUN = """
import sys, time
import cpas_ocp.estimation.solve as estimation
from cpas_ocp.cli import main

iterate = estimation.IterationMonitor.eval
def announced(self, arg):
    if self._k == 0:
        print("iterating", flush=True)
        time.sleep(2.0)
    return iterate(self, arg)
estimation.IterationMonitor.eval = announced
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_mid_solve_leaves_nothing_and_says_interrupted(sig, code, tmp_path) -> None:
    """Sent inside Ipopt (where an exception would read as a solver failure), the signal
    ends the run at the next iteration, or as the solver returns."""
    out = tmp_path / "demo"
    proc = subprocess.Popen([sys.executable, "-u", "-c", RUN, "demo", "--out", str(out),
                             "--max-iter", "500"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith("iterating"):
            break
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1].startswith("interrupted"), err
    assert "Traceback" not in err and "solver failed" not in err
    assert not (out / "report").exists() and not (out / "test").exists()
    assert not list(Path(out).glob(".cpas-out-*")) and not list(tmp_path.glob(".cpas-out-*"))


def test_orphaned_temporary_folders_are_swept_by_the_next_run(tmp_path) -> None:
    """A process killed outright leaves its `.cpas-out-<pid>-*` sibling; the next output
    written beside it removes it, and never a live process's."""
    import os

    from cpas_ocp.io.output_folder import atomic_folder

    dead = tmp_path / ".cpas-out-999999999-abc"  # no such process
    alive = tmp_path / f".cpas-out-{os.getpid()}-def"
    dead.mkdir()
    alive.mkdir()
    with atomic_folder(tmp_path / "out", "marker.txt") as tmp:
        (tmp / "marker.txt").write_text("x")
    assert not dead.exists() and alive.exists()
    assert (tmp_path / "out" / "marker.txt").exists()


def test_a_signal_inside_a_deferred_region_waits_for_its_end() -> None:
    """Inside `deferred` a signal only marks itself pending; leaving the region raises it,
    and outside one it raises at once."""
    import os

    from cpas_ocp import interrupts

    previous = {s: signal.getsignal(s) for s in interrupts.SIGNALS}
    interrupts.handle_signals()
    try:
        with pytest.raises(interrupts.Interrupted) as raised, interrupts.deferred():
            os.kill(os.getpid(), signal.SIGTERM)
            assert interrupts.pending()  # still running: the region is not left yet
        assert raised.value.exit_code == 143 and not interrupts.pending()
        with pytest.raises(interrupts.Interrupted):
            os.kill(os.getpid(), signal.SIGINT)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)



# The command line with the building of its parser announced and held up, so that the
# signal surely arrives while the parser is built (it imports CasADi: seconds).
EARLY = """
import sys, time
import cpas_ocp.cli as cli
import cpas_ocp.cli.arguments as arguments

build = arguments.parser
def announced():
    print("parsing", flush=True)
    time.sleep(5.0)
    return build()
arguments.parser = announced
sys.exit(cli.main(sys.argv[1:]))
"""


def _interrupted(err: str, code: int, returncode: int) -> None:
    """The process ended by the signal in order: its exit code, the one line, no traceback."""
    assert returncode == code, err
    assert err.strip().splitlines() == [
        f"interrupted ({signal.Signals(code - 128).name}); nothing written"], err


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_the_arguments_are_parsed_is_an_interrupt(sig, code, tmp_path) -> None:
    """The handlers are installed before the parser is built: a signal in a command's first
    seconds is no KeyboardInterrupt traceback (SIGINT) and no silent death (SIGTERM)."""
    proc = subprocess.Popen([sys.executable, "-u", "-c", EARLY, "demo", "--out",
                             str(tmp_path / "demo")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("parsing")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    _interrupted(err, code, proc.returncode)
    assert not (tmp_path / "demo").exists()


def _python_started(pid: int) -> bool:
    """Whether the interpreter `pid` has installed its own SIGINT handler (its start-up is
    done: a signal before it would kill the process outright, which no code can change)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    caught = int(next(line for line in status.splitlines()
                      if line.startswith("SigCgt:")).split()[1], 16)
    return bool(caught >> (signal.SIGINT - 1) & 1)


def test_the_command_line_imports_only_its_handlers_before_installing_them() -> None:
    """`python -m cpas_ocp.cli` imports the package and `cpas_ocp.cli` before `main` can
    install the handlers; what that loads is the time in which a Ctrl-C is Python's
    KeyboardInterrupt traceback.  The command line's own modules (the parser, the commands,
    the output folder's checks) are imported by `main`, after the handlers."""
    done = subprocess.run([sys.executable, "-c", "import sys, cpas_ocp.cli; print(sorted("
                           "m for m in sys.modules if m.startswith('cpas_ocp')))"],
                          capture_output=True, text=True, check=True)
    assert done.stdout.strip() == str(["cpas_ocp", "cpas_ocp.cli", "cpas_ocp.errors",
                                       "cpas_ocp.interrupts"])


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_ctrl_c_in_the_first_moments_of_the_command_line_is_an_interrupt(tmp_path) -> None:
    """`python -m cpas_ocp.cli` itself, Ctrl-C 0.2 s after the interpreter started."""
    proc = subprocess.Popen([sys.executable, "-m", "cpas_ocp.cli", "demo", "--out",
                             str(tmp_path / "demo")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    while not _python_started(proc.pid) and proc.poll() is None:
        time.sleep(0.01)
    time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    _interrupted(err, 130, proc.returncode)
    assert not (tmp_path / "demo").exists()


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
