"""Ctrl-C and SIGTERM end a command in order: exit 130 or 143, one line, nothing left behind."""

from __future__ import annotations

import os
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
