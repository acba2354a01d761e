"""The Python interface: one path from an estimator to a reconstruction, and a result that
shows itself (a line in a terminal, a table in a notebook, the command line's summary)."""

from __future__ import annotations

import math
import re

import cpas_ocp as co
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test


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
    assert rec.claim.text() in text
    assert f"AIC {crit.aic:.1f}" in text
