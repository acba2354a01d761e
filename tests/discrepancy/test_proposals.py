"""Plug-ins written from a signature: gated per canopy from that canopy's windows, and
asked for only by a signature of the sensor's own canopy or a shared quantity.

Findings are made by hand on a `drogue` fit (two canopies opening at different
times), so that what is proposed from a given signature is tested directly.
"""

from __future__ import annotations

import math
import runpy

from cpas_ocp.discrepancy.candidate_plugins import propose
from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.residual_diagnosis import PERIODICITY, Finding
from cpas_ocp.discrepancy.signatures import Correlation
from cpas_ocp.inference.phase_windows import phase_windows
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.physics.effects.registry import load_plugin


def _finding(sensor: str, channel: str, window, rejected: tuple[str, ...],
             correlations: list[Correlation] = (), frequency_hz: float = 1.6) -> Finding:
    return Finding(sensor, channel, window.name, window.t0, window.t1, 100, 1.5, 1e-9,
                   frequency_hz, 1e-12, None, None, None, list(correlations), True, 1e-9,
                   rejected)


def _diagnosis(fit, findings: list[Finding]) -> Diagnosis:
    return Diagnosis(fit, phase_windows(fit), [], [], findings)


def test_a_modulation_is_gated_per_canopy_from_its_own_windows(drogue_fit, tmp_path) -> None:
    fit, _, _ = drogue_fit(1)
    windows = {w.name: w for w in phase_windows(fit)}
    steady = sorted((w for w in windows.values() if w.kind == "steady"),
                    key=lambda w: (w.parachute, w.t0))
    last = {w.parachute: w for w in steady}  # each canopy's last steady window
    assert len(last) == 2 and len({w.t0 for w in last.values()}) == 2
    findings = [_finding(f"riser_{c}", "tension", w, (PERIODICITY,)) for c, w in last.items()]
    proposal = next(p for p in propose(_diagnosis(fit, findings), baseline_spec())
                    if p.name == "drag_area_modulation")
    path = tmp_path / proposal.file_name
    path.write_text(proposal.source)
    gates = runpy.run_path(str(path))["WINDOWS_S"]
    for canopy, w in last.items():
        end = math.inf if w.t1 >= float(fit.t[-1]) - 0.5 else w.t1
        assert gates[canopy] == (round(w.t0, 3), round(end, 3) if end < math.inf else end)
    assert "drag_area_modulation" in load_plugin(path)  # it loads as written


def test_a_load_cell_follows_its_own_canopy_not_the_other(drogue_fit) -> None:
    """drogue1's load cell correlating with drogue2's drag area asks for nothing; with its
    own drag area, or the shared dynamic pressure, it asks for a tension gain."""
    fit, _, _ = drogue_fit(1)
    window = next(w for w in phase_windows(fit) if w.parachute == "drogue1"
                  and w.kind == "steady")

    def proposed(signature: str) -> list[str]:
        c = Correlation(signature, "load level", 0.5, 1e-12, 100, 100.0)
        finding = _finding("riser_drogue1", "tension", window, (signature,), [c])
        return [p.name for p in propose(_diagnosis(fit, [finding]), baseline_spec())]

    assert "tension_gain" not in proposed("cds[drogue2]")
    assert "tension_gain" in proposed("cds[drogue1]")
    assert "tension_gain" in proposed("dynamic_pressure")
