"""Ctrl-C and SIGTERM end a command in order: exit 130 or 143, one line, nothing left behind."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

# The command, with Ipopt's first iteration callback announcing itself and then pausing, so
# that the signal surely arrives inside the solver whatever the machine's load.
RUN = """
import sys, time
import cpas_ocp.estimation.estimator as estimation
from cpas_ocp.cli import main

iterate = estimation._Monitor.eval
def announced(self, arg):
    if self._k == 0:
        print("iterating", flush=True)
        time.sleep(2.0)
    return iterate(self, arg)
estimation._Monitor.eval = announced
sys.exit(main(sys.argv[1:]))
"""


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

