"""The Python interface: one path from an estimator to a reconstruction, and a result that
shows itself (a line in a terminal, a table in a notebook, the command line's summary)."""

from __future__ import annotations

import math
import re

import pytest

import cpas_ocp as co
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.fit import EVENTS
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.reports.fit_text import claim_text

pytestmark = pytest.mark.slow  # fits of a whole phase


def test_a_reconstruction_shows_its_parameters_statistics_and_claim(drogue_folder) -> None:
    rec = co.reconstruct(drogue_folder(1))
    assert rec.fit.solver.success
    # The one path: reconstructing a folder equals fitting its estimator.
    again = co.fit_estimator(Estimator(load_test(drogue_folder(1))))
    assert math.isclose(again.fit.chi_square, rec.fit.chi_square, rel_tol=1e-9)

    crit = rec.criteria
    k, n = len(rec.fit.free), rec.fit.n_samples
    assert crit.k == k and crit.n == n
    assert math.isclose(crit.aic, rec.fit.chi_square + 2 * k)
    assert math.isclose(crit.bic, rec.fit.chi_square + k * math.log(n))

    line = repr(rec)
    assert line.startswith(f"<Reconstruction of {rec.fit.test.name}: {k} parameters, ")
    assert f"chi-square/dof {rec.chi_square_per_dof:.3f}" in line
    assert ("a result" if rec.is_result else "not a result") in line

    page = rec._repr_html_()
    assert page.count("<table") == 1
    for name in rec.fit.free:  # every free parameter is a row of the notebook's table
        assert re.search(rf"<th>{re.escape(name)}</th>", page), name
    assert f"{rec.chi_square_per_dof:.3f}" in page

    text = rec.summary()
    for name in rec.fit.free:
        assert name in text, name
    assert claim_text(rec.claim) in text
    assert f"AIC {crit.aic:.1f}" in text


def test_a_reconstruction_plots_profiles_constrains_and_extends_its_model(drogue_folder
                                                                          ) -> None:
    import matplotlib.pyplot as plt
    import numpy as np
    import pytest

    rec = co.reconstruct(drogue_folder(1))
    sensor = next(r.sensor for r in rec.fit.residuals if r.channel == "tension")
    rows = [r for r in rec.fit.residuals if r.sensor == sensor]
    axes = rec.plot(sensor)
    assert len(axes) == 2 * len(rows)
    # The residual axis carries the normalised residuals themselves.
    drawn = [line.get_ydata() for line in axes[1].get_lines() if len(line.get_ydata()) > 2]
    assert any(np.array_equal(y, rows[0].normalised) for y in drawn)
    plt.close(axes[0].figure)
    with pytest.raises(ValueError, match="no residuals of a sensor 'nothing'"):
        rec.plot("nothing")
    canopies = rec.plot_drag_areas()
    assert [ax.get_ylabel().split()[0] for ax in canopies] == [
        c.name for c in rec.fit.test.parachutes]
    events = rec.plot_events()
    seen = sorted((r for r in rec.fit.residuals if r.sensor == EVENTS),
                  key=lambda r: r.measured[0])  # the observed event times the fit sees
    # drogue's events place the start windows and are not fitted: nothing to draw.
    assert (events is None) == (not seen)
    if events is not None:
        assert [t.get_text() for t in events.get_yticklabels()] == [r.channel for r in seen]
    correlation = rec.plot_correlation()
    assert correlation is not None
    plt.close("all")

    extended = rec.spec_with("added_mass")
    assert "added_mass" in extended.effect_names
    assert set(rec.spec.effect_names) < set(extended.effect_names)
    with pytest.raises(ValueError, match="no effect 'no_such_effect'"):
        rec.spec_with("no_such_effect")

    name = next(n for n in rec.fit.free if n.startswith("Ck["))
    prof = rec.profile(name, span=1.0, points=3)
    assert prof.values[1] == pytest.approx(rec.fit.parameters[name])
    assert prof.delta_chi_square[1] == pytest.approx(0.0, abs=1e-3)
    # One sigma off the estimate the profile rises by about one (the quadratic prediction),
    # 0.5-2 allowing for the curvature the linearisation leaves out.
    assert all(0.5 < d < 2.0 for d in prof.delta_chi_square[[0, 2]]), prof.delta_chi_square
    ax = rec.plot_profile(prof)
    assert np.array_equal(ax.get_lines()[1].get_ydata(), prof.delta_chi_square)
    plt.close("all")

    held = rec.fit.parameters[name] + 2.0 * rec.covariance.std[name]
    result = rec.what_if(f"{name} == {held!r}")
    assert result.constrained.parameters[name] == pytest.approx(held, rel=1e-6)
    # Holding a parameter 2 sigma off costs about 4 in chi-square (as above, 2-8).
    assert 2.0 < result.delta_chi_square < 8.0, result.delta_chi_square


def test_a_reconstruction_discovers_with_the_commands_options(drogue_folder, tmp_path,
                                                              monkeypatch) -> None:
    import json

    from tests.cheap_discovery import cheap

    rec = co.reconstruct(drogue_folder(1))
    cheap(monkeypatch)  # one score test per step, no refits: the chain's bookkeeping
    ended = []
    found = rec.discover(tmp_path / "chain", max_steps=2, on_step=ended.append)
    assert len(found.steps) == 3  # the start and two added steps (the cheap chain adds one each)
    assert [s.label for s in ended] == [s.label for s in found.steps]
    assert found.steps[0].fit.chi_square == rec.fit.chi_square  # it starts from this fit
    written = json.loads((tmp_path / "chain" / "discovery.json").read_text())
    assert len(written["steps"]) == len(found.steps)
