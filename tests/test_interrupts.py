"""Ctrl-C and SIGTERM end a command in order: exit 130 or 143, one line, nothing left behind."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

RUN = "import sys; from cpas_ocp.cli import main; sys.exit(main(sys.argv[1:]))"


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_mid_solve_leaves_nothing_and_says_interrupted(sig, code, tmp_path) -> None:
    """Sent once the solve has begun (inside Ipopt, where an exception would read as a
    solver failure), the signal ends the run at the next iteration."""
    out = tmp_path / "demo"
    proc = subprocess.Popen([sys.executable, "-u", "-c", RUN, "demo", "--out", str(out),
                             "--max-iter", "500"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith("solving:"):
            break
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1].startswith("interrupted"), err
    assert "Traceback" not in err and "solver failed" not in err
    assert not (out / "report").exists()
    assert not list(Path(out).glob(".cpas-out-*")) and not list(tmp_path.glob(".cpas-out-*"))


def test_orphaned_temporary_folders_are_swept_by_the_next_run(tmp_path) -> None:
    """A process killed outright leaves its `.cpas-out-<pid>-*` sibling; the next output
    written beside it removes it, and never a live process's."""
    import os

    from cpas_ocp.output_folder import atomic_folder

    dead = tmp_path / ".cpas-out-999999999-abc"  # no such process
    alive = tmp_path / f".cpas-out-{os.getpid()}-def"
    dead.mkdir()
    alive.mkdir()
    with atomic_folder(tmp_path / "out", "marker.txt") as tmp:
        (tmp / "marker.txt").write_text("x")
    assert not dead.exists() and alive.exists()
    assert (tmp_path / "out" / "marker.txt").exists()
