"""The drag-area growth laws of paper Eqs. 5 and 6, and the n <-> n_p conversion."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.physics.inflation import (
    CORNER_S,
    fill_constant_from_peak,
    fill_length,
    finite_mass_cds,
    infinite_mass_cds,
    peak_fill_constant,
)

T0, PREV, CDS, CK, NP, E, TK, D, V = 1.0, 7.0, 12.0, 1.3, 5.0, 1.7, 0.25, 7.0, 100.0


def curve(t: float) -> float:
    return float(infinite_mass_cds(t, T0, PREV, CDS, CK, NP, E, TK, D, V))


def test_rises_from_previous_stage_to_peak_at_t_fp() -> None:
    t_fp = NP * D / V
    # The start is rounded: the curve leaves CdS_{i-1} CORNER_S before t_i, and by t_i
    # has grown no more than Eq. 5 grows in CORNER_S.
    assert curve(T0 - CORNER_S) == pytest.approx(PREV, rel=1e-9)
    x = (CK * CDS - PREV) / (CDS - PREV)
    assert PREV < curve(T0) < PREV + (CDS - PREV) * x * (CORNER_S / t_fp) ** E
    # outside the +-5 ms rounding the curve is exactly Eq. 5 ...
    tau = (t_fp - 2 * CORNER_S) / t_fp
    assert curve(T0 + tau * t_fp) == pytest.approx(PREV + (CDS - PREV) * x * tau**E, rel=1e-12)
    # ... and the peak is Ck * CdS_i to within the rounding.
    assert curve(T0 + t_fp) == pytest.approx(CK * CDS, rel=5e-3)


def test_a_guess_below_the_previous_stage_keeps_the_curve_finite() -> None:
    """A start that puts a stage's drag area at or below the previous stage's (a guess
    scaled by +-30 % can) gives a bounded curve between the two areas and the peak, not
    the 1e13 m^2 a division by the clamped growth made of it (which failed the first
    Ipopt iteration on `drogue`)."""
    t_fp = NP * D / V
    for cds in (PREV, 0.9 * PREV):
        values = [float(infinite_mass_cds(t, T0, PREV, cds, CK, NP, E, TK, D, V))
                  for t in np.linspace(T0 - 0.1, T0 + t_fp + 3 * TK, 200)]
        assert np.all(np.isfinite(values))
        assert min(values) >= min(PREV, cds) - 1e-9
        assert max(values) <= max(PREV, CK * cds) + 1e-9


def test_decays_per_eq6_and_settles_after_t_k() -> None:
    t_fp = NP * D / V
    t = T0 + t_fp + 0.1
    assert curve(t) == pytest.approx(CK * CDS * CK ** (-0.1 / TK), rel=1e-12)
    assert curve(T0 + t_fp + TK + 2 * CORNER_S) == pytest.approx(CDS, rel=1e-12)
    assert curve(T0 + 5.0) == pytest.approx(CDS, rel=1e-12)


def test_fill_constant_round_trip_and_meaning() -> None:
    n = float(fill_constant_from_peak(NP, PREV, CDS, CK, E))
    assert float(peak_fill_constant(n, PREV, CDS, CK, E)) == pytest.approx(NP, rel=1e-12)
    # Eq. 5 with the standard fill constant reaches Ck CdS_i at t_fp = n_p D / V.
    t_f = n * D / V
    t_fp = NP * D / V
    assert PREV + (CDS - PREV) * (t_fp / t_f) ** E == pytest.approx(CK * CDS, rel=1e-12)


def test_finite_mass_reaches_steady_value_at_t_f() -> None:
    n = 8.0
    t_f = n * D / V
    f = [float(finite_mass_cds(T0 + s * t_f, T0, PREV, CDS, n, 1.0, D, V)) for s in
         (0.5, 1.0, 2.0)]
    assert f == pytest.approx([0.5 * (PREV + CDS), CDS, CDS], rel=1e-12)


def test_growth_scaled_fill_length() -> None:
    length = float(fill_length("growth_scaled", D, PREV, CDS, 20.0))
    assert length == pytest.approx(D * np.sqrt((CDS - PREV) / 20.0))
    with pytest.raises(ValueError):
        fill_length("bogus", D, PREV, CDS, 20.0)  # type: ignore[arg-type]


def _largest_derivative_jump(corner_s: float) -> float:
    """Largest change of dCdS/dt_start between neighbouring start times 10 us apart,
    relative to the total change across the peak, for a sample at the peak."""
    import cpas_ocp.physics.inflation as inflation

    saved = inflation.CORNER_S
    inflation.CORNER_S = corner_s
    try:
        t0 = ca.SX.sym("t0")
        t_peak = T0 + NP * D / V
        expr = infinite_mass_cds(t_peak, t0, PREV, CDS, CK, NP, E, TK, D, V)
        d1 = ca.Function("d1", [t0], [ca.gradient(expr, t0)])
        shifts = np.arange(-2 * CORNER_S, 2 * CORNER_S, 1e-5)
        slopes = np.array([float(d1(T0 + s)) for s in shifts])
    finally:
        inflation.CORNER_S = saved
    return float(np.max(np.abs(np.diff(slopes))) / np.ptp(slopes))


def test_peak_corner_is_smooth_in_start_time() -> None:
    # Rounded: the slope turns over hundreds of steps; a kink turns it in one.
    assert _largest_derivative_jump(CORNER_S) < 0.02
    assert _largest_derivative_jump(1e-9) > 0.5


@pytest.mark.parametrize("law", ["finite", "infinite"])
def test_curves_have_no_kinks(law: str) -> None:
    """The slope is continuous through every rounded corner: no jump between neighbouring
    0.1 ms steps exceeds what the curvature of the smooth parts gives."""
    t = ca.SX.sym("t")
    if law == "finite":
        cds = finite_mass_cds(t, T0, PREV, CDS, 3.0, 1.2, D, V)
    else:
        cds = infinite_mass_cds(t, T0, PREV, CDS, CK, NP, E, TK, D, V)
    slope = ca.Function("slope", [t], [ca.jacobian(cds, t)])
    times = np.arange(T0 - 0.02, T0 + 1.0, 1e-4)
    s = np.array([float(slope(v)) for v in times])
    jumps = np.abs(np.diff(s))
    # a corner handled as a kink would jump by a sizeable part of the largest slope
    assert jumps.max() < 0.05 * np.abs(s).max()


def test_canopy_drag_area_is_the_law_of_its_last_started_stage(drogue_folder) -> None:
    """The model evaluates one stage's law at a time (its inputs selected by the stages'
    start times); value and every derivative equal the piecewise definition, each stage's
    Eq. 5-6 curve from CORNER_S before its start, the last stage started taking over, here
    with a third stage that starts during the second's rise and a second stage set to
    start before the first."""
    from cpas_ocp.io.flight_test import load_test
    from cpas_ocp.io.problems import load_problem
    from cpas_ocp.physics.effects import baseline_effects
    from cpas_ocp.physics.model import Model
    from cpas_ocp.physics.parameters import param_name

    model = Model(load_test(drogue_folder(1)), baseline_effects())
    chute = model.test.parachutes[0]
    assert chute.inflation == "infinite_mass" and len(chute.stages) == 3
    x, t = ca.SX.sym("x", model.nx), ca.SX.sym("t")
    p, c = ca.SX.sym("p", len(model.parameters)), ca.SX.sym("c", len(model.captures))
    names = model.parameter_names

    def par(kind: str, stage: str) -> ca.SX:
        return p[names.index(param_name(kind, chute.name, stage))]

    reference, prev = ca.SX(0.0), 0.0
    final = par("CdS", chute.stages[-1])
    for stage in chute.stages:
        steady = par("CdS", stage)
        law = infinite_mass_cds(
            t, par("t_start", stage), prev, steady, par("Ck", stage), par("n_p", stage),
            par("expopen", stage), par("t_k", stage),
            fill_length(chute.fill_length, chute.diameter, prev, steady, final),
            c[[cap.name for cap in model.captures].index(param_name("V_start", chute.name,
                                                                    stage))])
        reference = ca.if_else(t >= par("t_start", stage) - CORNER_S, law, reference)
        prev = steady
    cds = model.quantities(x, t, p, c)[model.quantity_names.index(f"cds[{chute.name}]")]
    both = ca.Function("both", [t, p, c], [cds, reference, ca.jacobian(cds, ca.vertcat(t, p)),
                                           ca.jacobian(reference, ca.vertcat(t, p))])

    truth = load_problem("drogue").truth
    t1, t2, t3 = (truth[param_name("t_start", chute.name, s)] for s in chute.stages)
    cases = {"as flown": dict(truth),
             "third starts in the second's rise": {
                 **truth, param_name("t_start", chute.name, chute.stages[2]): t2 + 0.15},
             "second starts before the first": {
                 **truth, param_name("t_start", chute.name, chute.stages[1]): t1 - 0.2}}
    speeds = np.full(len(model.captures), 80.0)
    times = np.concatenate([np.linspace(t1 - 0.5, t3 + 3.0, 1500),
                            [t1 - 0.2 - CORNER_S, t1 - CORNER_S, t2, t3]])
    for label, values in cases.items():
        pvec = model.parameter_vector(values)
        for tv in times:
            got, want, dgot, dwant = (np.asarray(v) for v in both(tv, pvec, speeds))
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-12, err_msg=label)
            np.testing.assert_allclose(dgot, dwant, rtol=1e-12, atol=1e-10, err_msg=label)
        assert np.asarray(both(t3 + 3.0, pvec, speeds)[0]).item() > 0.0
