"""The five public rocket logs of `../shared/data/rocketpy-logs/`, each imported from its
files as published with a card written from docs/flight-card.md (the built-in cards),
reconstructed with the default model, and judged as a rocketry user would: a result at
chi-square/dof at most 2 whose every fitted drag area agrees with its steady descent's
2 m g / (rho v^2) within their sigmas, or an exit 4 whose claim says in words what
happened (a canopy that did not open, one that needed more drag than its diameter gives,
which data disagree).  Prints each log's outcome and time.  Skips where the shared folder
is absent.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.cli import main
from tests.io.test_rocketpy_logs import DATA, LOGS

pytestmark = pytest.mark.skipif(not (DATA / "rocketpy-logs").is_dir(),
                                reason="../shared/data/rocketpy-logs is absent")


@pytest.mark.parametrize("card", sorted(LOGS))
def test_each_log_ends_in_a_result_or_says_what_happened(tmp_path: Path, card: str,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    start = time.perf_counter()
    assert main(["import", str(DATA / LOGS[card]), "--card", card,
                 "--out", str(tmp_path / "test")]) == 0
    code = main(["reconstruct", str(tmp_path / "test"), "--out", str(tmp_path / "report")])
    seconds = time.perf_counter() - start
    out = capsys.readouterr().out
    assert code in (0, 4), out
    result = json.loads((tmp_path / "report" / "result.json").read_text())
    claim = result["claim"]
    with capsys.disabled():
        print(f"\n{card}: exit {code}, {claim['verdict']}, chi-square/dof "
              f"{result['fit']['chi_square_per_dof']:.2f}, {seconds:.0f} s; "
              + "; ".join(claim["problems"][:2]))
    if code == 4:
        assert not claim["result"] and claim["problems"]
        return
    assert claim["result"] and result["fit"]["chi_square_per_dof"] <= 2.0
    report = (tmp_path / "report" / "report.md").read_text()
    steady = report.split("## Drag areas from the steady descent")[1]
    for name, estimate in result["parameters"].items():
        if not name.startswith("CdS[") or estimate.get("std") is None:
            continue
        assert np.isfinite(estimate["std"]) and 0.0 < estimate["std"] < estimate["value"]
        assert f"| {name} | " in steady
