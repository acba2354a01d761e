"""Wake deficit (pressure recovery fraction): a given PRF turns PRF*CdS into free-stream CdS.

Within one test PRF and the drag areas enter only as a product, so PRF is an
input.  Data are simulated in a wake with PRF = 0.85 for the FBCPs.  Told the
PRF (through the manifest's model block), the fit recovers the free-stream
drag areas; without it, the same data give PRF*CdS, with the same chi-square.
"""

from __future__ import annotations

import dataclasses
import json

import pytest

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects.registry import BASELINE

PRF = 0.85


@pytest.fixture(scope="module")
def in_the_wake(tmp_path_factory):
    problem = load_problem("fbcp")
    effects = ["canopy_inflation", {"effect": "wake_deficit", "prf": {"fbcp": PRF}},
               *BASELINE[1:]]
    manifest = {**problem.manifest, "model": {"effects": effects}}
    folder = tmp_path_factory.mktemp("wake") / "test"
    simulate_problem(dataclasses.replace(problem, manifest=manifest), folder, seed=4)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    test = load_test(folder)
    told = Estimator(test)
    told_fit = told.solve()
    untold = Estimator(test, baseline_spec())
    untold_fit = untold.solve()
    return truth, (told_fit, told.covariance(told_fit)), (untold_fit, untold.covariance(untold_fit))


@pytest.mark.slow  # a whole phase fitted
def test_given_prf_recovers_free_stream_drag_areas(in_the_wake) -> None:
    truth, (fit, cov), _ = in_the_wake
    assert fit.parameters["prf[fbcp1]"] == PRF and "prf[fbcp1]" not in fit.free
    for chute in ("fbcp1", "fbcp2"):
        name = f"CdS[{chute},stage1]"
        assert abs(fit.parameters[name] - truth[name]) < 4 * cov.std[name], name


@pytest.mark.slow  # a whole phase fitted
def test_without_prf_the_product_is_recovered_at_the_same_chi_square(in_the_wake) -> None:
    truth, (told, _), (fit, cov) = in_the_wake
    for chute in ("fbcp1", "fbcp2"):
        name = f"CdS[{chute},stage1]"
        assert abs(fit.parameters[name] - PRF * truth[name]) < 4 * cov.std[name], name
    # One product, two factorisations: the data cannot tell them apart.  Each fit stops
    # within 0.01 in chi-square of its optimum (the statistical stop), and the optima agree.
    assert fit.chi_square == pytest.approx(told.chi_square, abs=0.05)
