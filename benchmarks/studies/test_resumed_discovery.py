"""A discovery killed after its second step goes on with `--resume` as if never stopped.

`discover` runs in a process of its own on a `drogue` folder (a chain of real
fits made cheap: `cheap_discovery`) and is killed with SIGKILL, which nothing
can catch, as soon as its folder holds steps 0-2.  The folder must then read
back whole (each step's model file, fit and strict JSON), and `discover
--resume` must finish it with the same chain, the same chi-square at every step
and the same ending as a run never stopped.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.discrepancy.discovery_checkpoint import RESUME_FILE, read_checkpoint
from cpas_ocp.io.flight_test import load_test
from tests.cheap_discovery import cheap

HERE = Path(__file__).resolve().parents[1]


def _steps_on_disk(out: Path) -> int:
    try:
        return len(json.loads((out / RESUME_FILE).read_text())["steps"])
    except (OSError, ValueError):
        return 0


def _chain(out: Path) -> tuple[list, list, str]:
    def refuse(name: str) -> None:
        raise ValueError(name)

    result = json.loads((out / "discovery.json").read_text(), parse_constant=refuse)
    return ([s["added"] for s in result["steps"]], [s["chi_square"] for s in result["steps"]],
            result["ending"]["state"])


@pytest.mark.slow
def test_a_killed_discovery_resumes_as_if_never_stopped(drogue_folder, tmp_path, monkeypatch,
                                                       capsys) -> None:
    folder = drogue_folder(1)
    killed = tmp_path / "killed"
    # A killed process leaves its temporary folders: the child's go under the test's.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE.parent), *sys.path]),
           "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-m", "tests.cheap_discovery", "discover",
                             str(folder), "--out", str(killed), "--max-steps", "3"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        while _steps_on_disk(killed) < 3 and proc.poll() is None:
            time.sleep(0.2)
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    # Steps 0-2 read back whole, each with its model and fit.
    chain = read_checkpoint(killed, load_test(folder))
    assert len(chain.steps) == 3
    added, chi2, state = _chain(killed)
    assert added == [None, "gps_lag", "gps_lag"] and state == "in progress"
    assert [s.fit.chi_square for s in chain.steps] == pytest.approx(chi2, rel=1e-9)

    cheap(monkeypatch)
    assert main(["discover", "--resume", str(killed)]) == 0
    whole = tmp_path / "whole"
    assert main(["discover", str(folder), "--out", str(whole), "--max-steps", "3"]) == 0
    capsys.readouterr()
    resumed, uninterrupted = _chain(killed), _chain(whole)
    assert resumed[0] == uninterrupted[0] == [None, "gps_lag", "gps_lag", "gps_lag"]
    assert resumed[1] == pytest.approx(uninterrupted[1], rel=1e-9)
    assert resumed[2] == uninterrupted[2] == "stopped early"


@pytest.mark.parametrize("setup", ["missing", "not a discovery", "no test folder"])
def test_a_folder_that_cannot_be_resumed_is_one_line_exit_2(setup, tmp_path, capsys) -> None:
    """`--resume` of a folder that holds no discovery to go on from, or of none, or
    `discover` with neither a test folder nor `--resume`: exit 2, one line naming what is
    wrong, nothing written."""
    folder = tmp_path / "d"
    if setup == "not a discovery":
        folder.mkdir()
        (folder / "notes.txt").write_text("mine")
    args = ["discover", "--out", str(folder)] if setup == "no test folder" else \
        ["discover", "--resume", str(folder)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert ("--resume DIR" in err[0]) if setup == "no test folder" else (RESUME_FILE in err[0])
    assert sorted(p.name for p in tmp_path.rglob("*")) == (
        ["d", "notes.txt"] if setup == "not a discovery" else [])
