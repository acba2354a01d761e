"""Commands that need no estimator do not load it: the help texts and `import` start
without the estimator, matplotlib or the workflows they do not run (a few seconds of
imports on a 2-core machine, `benchmarks/command_start.py`).

Each command runs in a fresh interpreter, which then lists the heavy modules it loaded.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cpas_ocp.io.example_flight import fly
from tests.io.test_rocket_log_import import layout_arguments

ROOT = Path(__file__).resolve().parents[2]
# Modules only fits, reports and studies need.
HEAVY = ("matplotlib", "cpas_ocp.estimation.estimator", "cpas_ocp.estimation.transcription",
         "cpas_ocp.api.reconstruction", "cpas_ocp.campaign.dispersion_study",
         "cpas_ocp.discrepancy.discovery")

RUN = """
import contextlib, io, json, sys
from cpas_ocp.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        code = main(json.loads(sys.argv[1]))
    except SystemExit as exc:  # argparse's --help
        code = exc.code
print(json.dumps({"code": code, "heavy": [m for m in json.loads(sys.argv[2])
                                          if m in sys.modules]}))
"""


def loaded(args: list[str]) -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *sys.path])}
    done = subprocess.run([sys.executable, "-c", RUN, json.dumps(args), json.dumps(HEAVY)],
                          env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("args", [["--help"], ["import", "--help"], ["reconstruct", "--help"]])
def test_a_help_text_loads_no_estimator(args: list[str]) -> None:
    assert loaded(args) == {"code": 0, "heavy": []}


def test_an_import_loads_no_estimator(tmp_path: Path) -> None:
    args = [*layout_arguments("altus", fly(), tmp_path), "--out", str(tmp_path / "test")]
    assert loaded(args) == {"code": 0, "heavy": []}
    assert (tmp_path / "test" / "manifest.json").is_file()


def test_a_fit_still_finds_its_workflow() -> None:
    """The interface's names resolve on first use, each to its module's own object."""
    import cpas_ocp as co
    from cpas_ocp import api
    from cpas_ocp.api import flights, log_import, reconstruction

    assert co.reconstruct is api.reconstruct is reconstruction.reconstruct
    assert api.import_log is log_import.import_log and api.flight is flights.flight
    # The literal __all__ (for static tools) and the lazy map name the same interface.
    assert sorted(api.__all__) == sorted(api._HOMES) and set(api.__all__) <= set(dir(api))
    assert all(getattr(api, name) is not None for name in api.__all__)  # each one resolves
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = api.nothing
