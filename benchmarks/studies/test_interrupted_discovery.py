"""A discovery stopped by a signal keeps the steps it finished.

`discover` on a `drogue` folder is stopped by SIGTERM while it diagnoses its
second step.  The command must exit 128 + 15, say on one line how many finished
steps it wrote, and leave a discovery folder with each finished step's model
file and a strict JSON chain whose state is "stopped early" and which says it
was interrupted.  The second step is the first fit again under another name (the
refit is not what is tested here), so the test costs one fit and one diagnosis.
"""

from __future__ import annotations

import json
import signal

import pytest

from cpas_ocp.cli import main
from cpas_ocp.discrepancy import discovery
from cpas_ocp.interrupts import Interrupted
from cpas_ocp.io.model_spec import load_model_file
from tests.conftest import DISCOVER_HOMES, patch_everywhere

pytestmark = pytest.mark.slow  # a discovery


def test_a_signal_keeps_the_finished_steps(drogue_folder, tmp_path, monkeypatch, capsys
                                           ) -> None:
    real_diagnose, real_discover = discovery.diagnose, discovery.discover
    calls, specs = [], []

    def diagnose(fit, spec, candidates, confirm_top, *args, **kwargs):
        calls.append(fit)
        if len(calls) == 2:
            raise Interrupted(signal.SIGTERM)
        return real_diagnose(fit, spec, candidates, 0, *args, **kwargs)  # no refits

    def next_step(diag, progress=False):
        return discovery.DiscoveryStep("gps_lag", specs[0], diag.fit, "in place of a refit")

    def discover(fit, spec, *args, **kwargs):
        specs.append(spec)
        return real_discover(fit, spec, *args, **kwargs)

    monkeypatch.setattr(discovery, "diagnose", diagnose)
    monkeypatch.setattr(discovery, "next_step", next_step)
    patch_everywhere(monkeypatch, "discover", discover, DISCOVER_HOMES)
    out = tmp_path / "d"
    code = main(["discover", str(drogue_folder(1)), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 128 + signal.SIGTERM
    assert "interrupted (SIGTERM); the 2 finished step(s) written to" in err
    assert len(err.strip().splitlines()) == 1, err

    def refuse(name: str) -> None:
        raise ValueError(name)

    result = json.loads((out / "discovery.json").read_text(), parse_constant=refuse)
    assert result["ending"]["state"] == "stopped early"
    assert "interrupted (SIGTERM)" in result["stopped"]
    assert [s["added"] for s in result["steps"]] == [None, "gps_lag"]
    for k in range(2):
        load_model_file(out / f"step_{k}.json")
    assert "interrupted (SIGTERM)" in (out / "discovery.md").read_text()
