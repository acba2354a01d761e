"""Plug-ins written from a signature: gated per canopy from that canopy's windows, and
asked for only by a signature of the sensor's own canopy or a shared quantity.

Findings are made by hand on a `drogue` fit (two canopies opening at different
times), so that what is proposed from a given signature is tested directly.
"""

from __future__ import annotations

import math
import runpy

import numpy as np

from cpas_ocp.discrepancy.candidate_plugins import propose
from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.residual_diagnosis import PERIODICITY, Finding
from cpas_ocp.discrepancy.signatures import Correlation
from cpas_ocp.inference.phase_windows import phase_windows
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.registry import load_plugin
from cpas_ocp.physics.model import Model


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


def _misfit(fit, findings: list[Finding]) -> Diagnosis:
    """A diagnosis of `fit` with `findings`, whose window (of the first) holds a chi-square
    of 4 per sample: a misfit that sits there."""
    from scipy.stats import chi2

    from cpas_ocp.discrepancy.diagnosis import ALPHA
    from cpas_ocp.inference.diagnostics import WindowStatistic
    from cpas_ocp.inference.noise_test import NoiseTest

    f = findings[0]
    window = WindowStatistic(f.sensor, f.channel, f.window, f.t0, f.t1, 100, 1.0, 2.0, 400.0,
                             0.01)
    chi = fit.dof + 300.0
    noise = NoiseTest(chi, fit.dof, float(chi2.sf(chi, fit.dof)), ALPHA, 1, [window])
    return Diagnosis(fit, phase_windows(fit), [window], [], findings, _noise=noise)


def test_what_a_chain_says_it_proposes_is_written(drogue_fit, tmp_path) -> None:
    """A line of two cycles in its window asks for no plug-in: the misfit's advice says
    `discover` wrote none, and the discovery folder has no proposed/.  A line of many
    cycles asks for a drag-area modulation: the advice names proposed/ and its file, and
    the folder holds it (the advice said "`discover` proposes some" of both)."""
    from cpas_ocp.discrepancy.diagnosis import ALPHA
    from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, _proposed_step
    from cpas_ocp.reports.discrepancy_report import write_discovery

    fit, _, _ = drogue_fit(1)
    window = max((w for w in phase_windows(fit) if w.kind == "steady"),
                 key=lambda w: w.t1 - w.t0)
    for cycles, written in ((2.0, []), (20.0, ["drag_area_modulation.py"])):
        finding = _finding("riser_drogue1", "tension", window, (PERIODICITY,),
                           frequency_hz=cycles / (window.t1 - window.t0))
        diag = _misfit(fit, [finding])
        chain = Discovery([DiscoveryStep(None, baseline_spec(), fit, diagnosis=diag)],
                          state="misfit", stopped="nothing left is confirmed")
        folder = tmp_path / f"{cycles:g}"
        folder.mkdir()
        _proposed_step(chain, chain.steps[0], folder, ALPHA, False)
        verdict = diag.verdict()
        assert "proposes some" not in verdict, verdict
        assert diag.proposed == written
        out = write_discovery(chain, tmp_path / f"discovery{cycles:g}", figures=False)
        if written:
            assert "`discover` wrote proposed/drag_area_modulation.py" in verdict, verdict
            assert (out / "proposed" / "drag_area_modulation.py").is_file()
        else:
            assert "`discover` wrote none" in verdict, verdict
            assert not (out / "proposed").exists()


def test_a_proposed_modulation_refines_to_its_own_start_and_is_itself_at_the_null(
        drogue_fit, tmp_path) -> None:
    """The written modulation offers one refinement: each canopy's start estimated, null at
    its window's start.  At the null the refined riser tensions are the written plug-in's;
    with a start 1 s later the tensions are unmodulated over that second and the same after
    (the phase keeps its reference at the window's start)."""
    fit, _, _ = drogue_fit(1)
    windows = {w.name: w for w in phase_windows(fit)}
    last = {w.parachute: w for w in sorted((w for w in windows.values() if w.kind == "steady"),
                                           key=lambda w: (w.parachute, w.t0))}
    findings = [_finding(f"riser_{c}", "tension", w, (PERIODICITY,)) for c, w in last.items()]
    proposal = next(p for p in propose(_diagnosis(fit, findings), baseline_spec())
                    if p.name == "drag_area_modulation")
    path = tmp_path / proposal.file_name
    path.write_text(proposal.source)
    written = load_plugin(path)["drag_area_modulation"].build({}, str(path), "test")
    (refinement,) = written.refinements(fit.test)
    assert refinement.effect.refinements(fit.test) == []
    assert refinement.null == {f"modulation_start[{c}]": round(w.t0, 3) for c, w in last.items()}
    base = baseline_effects()
    values = {**fit.parameters, **{f"modulation_{part}[{c}]": 0.05 for c in last
                                   for part in ("cos", "sin")}, "modulation_frequency": 1.6}
    plain = Model(fit.test, [base[0], written, *base[1:]])
    refined = Model(fit.test, [base[0], refinement.effect, *base[1:]])
    at = plain.quantities_along(fit.t, fit.x, values, fit.captures)
    at_null = refined.quantities_along(fit.t, fit.x, {**values, **refinement.null},
                                       fit.captures)
    later = {n: v + 1.0 for n, v in refinement.null.items()}
    delayed = refined.quantities_along(fit.t, fit.x, {**values, **later}, fit.captures)
    still = plain.quantities_along(fit.t, fit.x, {**values, **{
        n: 0.0 for n in values if n.startswith(("modulation_cos", "modulation_sin"))}},
        fit.captures)
    for canopy, w in last.items():
        load = f"tension[{canopy}]"
        np.testing.assert_allclose(at_null[load], at[load], rtol=1e-12)
        start = round(w.t0, 3)
        gap = (fit.t > start + 0.2) & (fit.t < start + 0.8)
        after = fit.t > start + 1.3
        assert np.max(np.abs(at[load][gap] - still[load][gap])) > 1e-3 * np.max(at[load][gap])
        np.testing.assert_allclose(delayed[load][gap], still[load][gap], rtol=1e-6)
        np.testing.assert_allclose(delayed[load][after], at[load][after], rtol=1e-9)
