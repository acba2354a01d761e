"""Stand-ins put into the package by a test are taken out again.

A module imported for the first time while a name it imports is patched binds the
stand-in (`from ... import name`); a string-target monkeypatch of that module then
records the stand-in as the value to restore.  The package's interface imports its
workflows on first use, so which module comes first depends on which tests ran before
in the same process: a stand-in fit left behind this way once made a later test compare
another test's data.  Checked in a fresh interpreter, where nothing is imported yet.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # two fresh interpreters importing the workflows: 10 s

ROOT = Path(__file__).parents[1]

SCRIPT = """
import pytest
import cpas_ocp.api.reconstruction
from tests.conftest import patch_everywhere, stand_ins_left
from tests.test_stand_ins import stand_in

with pytest.MonkeyPatch.context() as patch:
    {patch}
print(stand_ins_left())
"""
ONE_AT_A_TIME = ('for w in ("reconstruction", "discrepancy"):\n'
                 '        patch.setattr(f"cpas_ocp.api.{w}.fit_estimator", stand_in)')
EVERYWHERE = ('patch_everywhere(patch, "fit_estimator", stand_in, '
              '("cpas_ocp.api.reconstruction", "cpas_ocp.api.discrepancy"))')


def stand_in(*_args: object, **_kwargs: object) -> None:
    """What the patches put in place of the interface's fit."""


def left_after(patch: str) -> str:
    """What `stand_ins_left` lists after `patch` is applied and undone in a new process."""
    done = subprocess.run([sys.executable, "-c", SCRIPT.format(patch=patch)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_patching_one_module_at_a_time_leaves_the_stand_in_behind() -> None:
    assert left_after(ONE_AT_A_TIME) == "['cpas_ocp.api.discrepancy.fit_estimator']"


def test_patching_every_home_after_importing_them_leaves_nothing() -> None:
    assert left_after(EVERYWHERE) == "[]"
