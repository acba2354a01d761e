"""Added mass (paper Eq. 1): its size, and the load it adds while a canopy grows."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import chi2

from cpas_ocp.discrepancy.diagnosis import ALPHA
from cpas_ocp.discrepancy.refinement import best_kept, refine
from cpas_ocp.estimation.estimator import STATISTICALLY_CONVERGED, Estimator
from cpas_ocp.estimation.simulate import initial_state, simulate, simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_from_effects
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import AddedMass, baseline_effects
from cpas_ocp.physics.effects.added_mass import (
    EXPONENT,
    K_APPARENT,
    K_ENCLOSED,
    PROJECTED_RATIO,
)
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name
from tests.conftest import START_GUESS_OFFSET_S, offset_events

FACTOR = 1.4


@pytest.fixture(scope="module")
def runs(drogue_folder):
    """The drogue phase simulated from the same start with and without added mass."""
    test = load_test(drogue_folder(1))
    problem = load_problem("drogue")
    truth = {**problem.truth, **{param_name("added_mass_factor", c.name): FACTOR
                                 for c in test.parachutes}}
    sim = problem.simulation
    out = {}
    for label, effects in (("rigid", baseline_effects()),
                           ("added", [*baseline_effects(), AddedMass()])):
        model = Model(test, effects)
        traj = simulate(model, truth, initial_state(model, sim), float(sim["t_begin"]),
                        float(sim["t_end"]), 1e-3)
        out[label] = (traj, model.quantities_along(traj.t, traj.x, truth, traj.captures))
    return test, truth, out


def test_added_mass_of_a_full_open_canopy(runs) -> None:
    test, truth, out = runs
    traj, q = out["added"]
    chute = test.parachutes[0]
    steady = traj.t > truth[param_name("t_start", chute.name, chute.stages[-1])] + 2.0
    cds = q[param_name("cds", chute.name)][steady]
    cds_o = truth[param_name("CdS", chute.name, chute.stages[-1])]
    diameter = PROJECTED_RATIO * chute.diameter * np.sqrt((cds + 1e-4) / cds_o)
    expected = (FACTOR * q["density"][steady] * math.pi * diameter**3
                * (K_ENCLOSED / 12 + K_APPARENT / 8))
    np.testing.assert_allclose(q[param_name("added_mass", chute.name)][steady], expected,
                               rtol=1e-9)
    # A 23 ft canopy at ~7 km carries on the order of 50 kg of air.
    assert 20.0 < float(np.median(expected)) < 150.0


def test_a_size_exponent_grows_the_air_mass_as_that_power_through_the_fill(runs) -> None:
    """With `size_exponent` e the air mass at drag area CdS is the full-open one times
    (CdS / CdS_o)^(e / 2): at e = 6, during the first stage (CdS about a third of the
    last stage's), under half the D^3 law's; once full open the same (to the 2 % the
    two runs' densities may differ by)."""
    test, truth, _ = runs
    problem = load_problem("drogue")
    sim = problem.simulation
    model = Model(test, [*baseline_effects(), AddedMass(size_exponent=6.0)])
    traj = simulate(model, truth, initial_state(model, sim), float(sim["t_begin"]),
                    float(sim["t_end"]), 1e-3)
    q = model.quantities_along(traj.t, traj.x, truth, traj.captures)
    chute = test.parachutes[0]
    cds = q[param_name("cds", chute.name)]
    cds_o = truth[param_name("CdS", chute.name, chute.stages[-1])]
    full = (FACTOR * q["density"] * math.pi * (PROJECTED_RATIO * chute.diameter)**3
            * (K_ENCLOSED / 12 + K_APPARENT / 8))
    expected = full * ((cds + 1e-4) / cds_o) ** 3.0
    np.testing.assert_allclose(q[param_name("added_mass", chute.name)], expected, rtol=1e-9)
    # Against the D^3 law's air mass along its own run (the same clock): far smaller while
    # the canopy is a third open, the same once full open.
    d3 = runs[2]["added"][1][param_name("added_mass", chute.name)]
    first = (traj.t > truth[param_name("t_start", chute.name, chute.stages[1])] - 1.0) \
        & (traj.t < truth[param_name("t_start", chute.name, chute.stages[1])])
    assert np.all(q[param_name("added_mass", chute.name)][first] < 0.5 * d3[first])
    steady = traj.t > truth[param_name("t_start", chute.name, chute.stages[-1])] + 2.0
    np.testing.assert_allclose(q[param_name("added_mass", chute.name)][steady], d3[steady],
                               rtol=0.02)
    with pytest.raises(ValueError, match="size_exponent"):
        AddedMass(size_exponent=0.0)


def test_the_refined_law_is_the_fixed_one_at_its_null_and_grows_as_its_exponent(runs
                                                                                   ) -> None:
    """The refinement frees the exponent (``added_mass_exponent``) with its null at the
    fixed law's value: there the air mass along the D^3 run is the D^3 law's exactly; at
    6 it is the D^6 law's.  A refined effect offers no refinement of its own."""
    test, truth, out = runs
    traj, q = out["added"]
    fixed = AddedMass()
    (refinement,) = fixed.refinements(test)
    assert refinement.null == {EXPONENT: 3.0}
    assert refinement.effect.refinements(test) == []
    model = Model(test, [*baseline_effects(), refinement.effect])
    assert EXPONENT in model.parameter_names
    chute = test.parachutes[0]
    name = param_name("added_mass", chute.name)
    at_null = model.quantities_along(traj.t, traj.x, {**truth, **refinement.null},
                                     traj.captures)
    np.testing.assert_allclose(at_null[name], q[name], rtol=1e-12)
    at_six = model.quantities_along(traj.t, traj.x, {**truth, EXPONENT: 6.0}, traj.captures)
    d6 = Model(test, [*baseline_effects(), AddedMass(size_exponent=6.0)]).quantities_along(
        traj.t, traj.x, truth, traj.captures)
    np.testing.assert_allclose(at_six[name], d6[name], rtol=1e-12)
    assert not np.allclose(at_six[name], q[name], rtol=1e-3)


def test_riser_gathers_the_air_while_the_canopy_grows(runs) -> None:
    test, truth, out = runs
    chute = test.parachutes[0]
    tension = param_name("tension", chute.name)
    t = out["added"][0].t
    for stage in chute.stages:
        t_i = truth[param_name("t_start", chute.name, stage)]
        rise = (t > t_i) & (t < t_i + 0.25)
        more = out["added"][1][tension][rise] - out["rigid"][1][tension][rise]
        # While the drag area grows, d(m_A)/dt V adds to the load: the peak is higher.
        assert np.max(out["added"][1][tension][rise]) > np.max(out["rigid"][1][tension][rise])
        assert np.max(more) > 0.02 * np.max(out["rigid"][1][tension][rise])
    # Long after the last stage the canopy no longer grows: the two loads differ only
    # by the slow deceleration of m_A (the trajectories differ slightly too).
    late = t > t[-1] - 2.0
    diff = np.abs(out["added"][1][tension][late] - out["rigid"][1][tension][late])
    assert np.max(diff) < 0.02 * np.mean(out["rigid"][1][tension][late])


@pytest.fixture(scope="module")
def fbcp_with_added_mass(tmp_path_factory):
    """fbcp seed 1 made with added mass (k_A = 1.4), events 0.3 s off; fits with and without."""
    problem = load_problem("fbcp")
    truth = {**problem.truth, **{param_name("added_mass_factor", c["name"]): FACTOR
                                 for c in problem.manifest["parachutes"]}}
    root = tmp_path_factory.mktemp("fbcp-added-mass")
    simulate_problem(dataclasses.replace(problem, truth=truth), root / "sim", 1,
                     effects=[*baseline_effects(), AddedMass()])
    test = load_test(offset_events(root / "sim", root / "test", START_GUESS_OFFSET_S))
    with_it = Estimator(test, [*baseline_effects(), AddedMass()])
    fit = with_it.solve()
    without = Estimator(test).solve()
    return truth, fit, with_it.covariance(fit), without


@pytest.mark.slow  # a whole phase fitted
def test_added_mass_recovered_from_the_reduction(fbcp_with_added_mass) -> None:
    """Every parameter, the two added-mass factors included, within the noise of the truth.

    Same tolerances as the fbcp recovery test: squared Mahalanobis distance
    below the chi-square 0.999 quantile, every estimate within 4 sigma.
    """
    truth, fit, cov, _ = fbcp_with_added_mass
    assert fit.solver.status == STATISTICALLY_CONVERGED
    assert {param_name("added_mass_factor", c.name) for c in fit.test.parachutes} <= set(fit.free)
    z = {n: (fit.parameters[n] - truth[n]) / cov.std[n] for n in fit.free}
    worst = max(z, key=lambda n: abs(z[n]))
    assert abs(z[worst]) < 4.0, f"{worst}: {z[worst]:.2f} sigma"
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    assert m2 < chi2.ppf(0.999, dof), f"Mahalanobis^2 {m2:.1f} on {dof} dof"
    # Measured on 10 % of the nominal value or better: the data do see the air mass.
    assert all(cov.std[n] < 0.1 for n in fit.free if n.startswith("added_mass_factor"))


@pytest.mark.slow  # a whole phase fitted
def test_fit_without_added_mass_is_rejected(fbcp_with_added_mass) -> None:
    """Leaving added mass out of the model costs far more than its two parameters buy.

    The likelihood-ratio statistic (chi-square difference, nested models) is
    compared with the chi-square 0.999 quantile for 2 degrees of freedom.
    """
    _, fit, _, without = fbcp_with_added_mass
    assert without.solver.success
    delta = without.chi_square - fit.chi_square
    assert delta > chi2.ppf(0.999, 2), f"delta chi-square {delta:.1f}"
    assert without.chi_square / without.dof > fit.chi_square / fit.dof


@pytest.mark.slow  # a refinement refitted from three starts
def test_the_library_law_is_kept_unrefined_where_it_is_the_truth(fbcp_with_added_mass) -> None:
    """Data made with the D^3 law and fitted with it: the freed exponent's likelihood
    ratio does not pass the family-wise level, so the law stays as it is."""
    _, fit, _, _ = fbcp_with_added_mass
    spec = spec_from_effects([*baseline_effects(), AddedMass()])
    (trial,) = refine(fit, spec, ["added_mass"], 1, ALPHA)
    assert trial.lr is not None, trial.note
    assert not trial.kept, str(trial)
    assert best_kept([trial]) is None


@pytest.mark.slow  # a whole phase fitted, then refined
def test_a_wrong_growth_law_is_refined_to_the_exponent_that_made_the_data(
        fbcp_with_added_mass) -> None:
    """The same data fitted with a D^6 law: the refinement frees the exponent, its
    likelihood ratio passes, and the estimate lies within 4 sigma of the 3 that made
    the data (sigma from the refined fit's covariance)."""
    _, fit, _, _ = fbcp_with_added_mass
    spec = spec_from_effects([*baseline_effects(), AddedMass(size_exponent=6.0)])
    wrong = Estimator(fit.test, spec).solve()
    (trial,) = refine(wrong, spec, ["added_mass"], 1, ALPHA)
    assert trial.kept and trial.refitted is not None, str(trial)
    est, refined = trial.refitted
    sigma = est.covariance(refined).std[EXPONENT]
    assert abs(refined.parameters[EXPONENT] - 3.0) < 4.0 * sigma, str(trial)
