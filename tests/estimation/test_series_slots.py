"""The estimator's model local in time: a wind process's knots read a few per shooting
interval give the very residuals, constraints and Jacobian values of the model that sums
every knot everywhere, with only the knots about each row in its Jacobian."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.series_slots import offset_reach
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_block


@pytest.fixture(scope="module")
def wind_estimators(problem_folder, tmp_path_factory) -> dict[bool, Estimator]:
    """rocket_gusts (seed 2) fitted with the air's vertical motion, knots every 4 s, the
    altimeter's lag free (a sensor reading the state at another time): global and local."""
    folder = problem_folder("rocket_gusts", 2)
    model = json.loads((folder / "manifest.json").read_text())["model"]
    model["effects"] = [{"effect": "wind_process", "components": ["up"], "knot_s": 4.0,
                         "tau_s": 10.0, "sigma_vertical": 1.0}, *model["effects"], "baro_lag"]
    spec = spec_from_block(model, "model.json", tmp_path_factory.mktemp("model"))
    test = load_test(folder)
    return {local: Estimator(test, spec, settings=Settings(local_series=local, compile=False))
            for local in (False, True)}


def test_local_knots_give_the_same_values_and_jacobians(wind_estimators) -> None:
    glob, local = (wind_estimators[k].transcription for k in (False, True))
    assert glob.slots is None and local.slots is not None
    knots = [f for f in local.free if f.startswith("wind_up[")]
    assert local.slots.slots < len(knots)
    z = wind_estimators[False].initial_point()
    z = z * (1.0 + 1e-3 * np.random.default_rng(3).standard_normal(z.size))
    for name in ("residual_value", "residual_jacobian", "constraint_value", "constraints"):
        a, b = getattr(glob.points, name)(z), getattr(local.points, name)(z)
        for x, y in zip(a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,),
                        strict=True):
            if hasattr(x, "toarray"):
                assert y.nnz < x.nnz
                x, y = x.toarray(), y.toarray()
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    # Every sensor row and continuity gap reads at most `slots` knots.
    n_states = local.sizes[0]
    cols = [n_states + local.free.index(k) for k in knots]
    for jac in (local.points.residual_jacobian(z)[1], local.points.constraints(z)[1]):
        per_row = (jac.tocsc()[:, cols] != 0).sum(axis=1)
        assert np.max(per_row) <= local.slots.slots


def test_a_lag_widens_the_knots_read_by_its_reach(wind_estimators) -> None:
    """The altimeter's lag reads the state up to its bound away: so far beyond each
    interval the knots are read."""
    tr = wind_estimators[True].transcription
    lag = next(p for p in tr.model.parameters if p.name.startswith("lag["))
    assert offset_reach(tr.model, tr.values, tr.free) == pytest.approx(
        max(abs(lag.lower), abs(lag.upper)))
