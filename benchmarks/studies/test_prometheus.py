"""The Prometheus rocket's real logs: import, reconstruction and the flight comparison.

The logs are read from the shared data folder and never copied; without it
every test here skips with the reason.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.discrepancy.common_residual import combined_p_value, common_residuals
from cpas_ocp.discrepancy.diagnosis import ALPHA
from cpas_ocp.discrepancy.wind_evidence import DECISIVE_2LNB, wind_evidence
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.inference.process_intensity import without_wind
from cpas_ocp.inference.profile_likelihood import THRESHOLD
from cpas_ocp.io.altus_metrum import read_altus_log
from cpas_ocp.io.flight_card import load_card
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.opening_loads import OPENING_WINDOW_S
from cpas_ocp.io.recorder_clocks import clock_offset
from cpas_ocp.reports.flight_report import (
    descent_rates,
    flight_text,
    held_opening_profiles,
    nominal_comparisons,
)

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "prometheus-2022"
MEGA = "telemega-serial-6583-flight-0003.csv"
METRUM = "telemetrum-serial-5115-flight-0001.csv"

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    not (DATA / MEGA).is_file(),
    reason=f"the Prometheus flight logs are not at {DATA} (shared data folder absent)")]


@pytest.mark.parametrize("log_name, recorder", [(MEGA, "TeleMega"), (METRUM, "TeleMetrum")])
def test_both_recorders_import(tmp_path: Path, log_name: str, recorder: str) -> None:
    log = read_altus_log(DATA / log_name)
    assert log.recorder == recorder
    summary = import_flight(log, load_card("prometheus"), tmp_path / "test")
    test = load_test(tmp_path / "test")
    # Published facts: drogue at apogee (~28.5 s), main at 457 m AGL (~158 s).
    assert summary.events["drogue"] == pytest.approx(28.5, abs=1.5)
    assert summary.events["main"] == pytest.approx(158.0, abs=0.5)
    # The 1401 m site on a hot June afternoon: 300 K from the published 1.001 kg/m^3, and
    # a lapse rate between the standard 6.5 K/km and the dry adiabat.
    assert summary.site.temperature_k == pytest.approx(300.5, abs=0.5)
    assert 6.5e-3 < summary.site.lapse_rate_k_m < 9.8e-3
    assert summary.lapse_fit is not None and summary.lapse_fit[2] < 10.0
    # Under the 30 m/s drogue the altimeter scatters more than under the 7 m/s main.
    assert summary.baro_sigma_m[0] > 2.0 * summary.baro_sigma_m[1]
    assert test.t_end < summary.events["touchdown"]


def _reconstruct(tmp_path_factory: pytest.TempPathFactory, log_name: str, still: bool = False):
    """(fit, covariance) of one log imported under the Prometheus card: its model, which
    estimates the air's vertical motion, or (`still`) that model in still air."""
    folder = tmp_path_factory.mktemp(Path(log_name).stem) / "test"
    import_flight(read_altus_log(DATA / log_name), load_card("prometheus"), folder)
    test = load_test(folder)
    spec = spec_of_test(test)
    est = Estimator(test, without_wind(spec, test) if still else spec)
    fit = est.solve()
    return fit, est.covariance(fit)


@pytest.fixture(scope="module")
def mega_fit(tmp_path_factory: pytest.TempPathFactory):
    return _reconstruct(tmp_path_factory, MEGA)


@pytest.fixture(scope="module")
def metrum_fit(tmp_path_factory: pytest.TempPathFactory):
    return _reconstruct(tmp_path_factory, METRUM)


@pytest.fixture(scope="module")
def mega_still(tmp_path_factory: pytest.TempPathFactory):
    return _reconstruct(tmp_path_factory, MEGA, still=True)


def _full_open(fit) -> tuple[float, float]:
    """The import's reading of the main's opening peak (s): its time (``import.json``
    ``events_s``) and, as its sigma, the accelerometer's median sample interval within
    the window the import searched (`OPENING_WINDOW_S` after the charge).  With an
    accelerometer in the folder the peak is not a ``full_open`` event: the fit reads the
    opening from the samples themselves."""
    peak = json.loads((fit.test.path / "import.json").read_text())["events_s"]["main full open"]
    charge = fit.test.event("mortar_fire", "main").time
    t = fit.test.sensors_of("axial_accelerometer")[0].time
    inside = t[(t >= charge) & (t <= charge + OPENING_WINDOW_S)]
    return float(peak), float(np.median(np.diff(inside)))


def _opening(fit) -> tuple[float, float]:
    """The main's opening (s): from its charge through the window in which the import looks
    for its load peak (`OPENING_WINDOW_S`)."""
    charge = fit.test.event("mortar_fire", "main").time
    return charge, charge + OPENING_WINDOW_S


def test_both_logs_fit_their_noise_with_the_air_motion_and_the_accelerometer(
        mega_fit, metrum_fit) -> None:
    """With the wind process and the accelerometer in the model, each log fits its sensors
    to chi2/dof <= 1.5 (sigmas from the import's scatter rule, not scaled), and the
    accelerometer, a fitted sensor, fits the main's opening to a normalised RMS <= 1.5
    (with 5 values its square exceeds 2.25 by chance with probability 0.05)."""
    for fit, _ in (mega_fit, metrum_fit):
        assert fit.chi_square / fit.dof <= 1.5
        accel = next(r for r in fit.residuals if r.sensor == "accelerometer")
        lo, hi = _opening(fit)
        opening = (accel.t >= lo) & (accel.t < hi)
        # The import merges straight stretches into means (each worth several 10 Hz
        # samples): the window holds a few of them, enough for an RMS to test.
        assert opening.sum() >= 5
        assert np.sqrt(np.mean(accel.normalised[opening] ** 2)) <= 1.5


def test_two_recorders_agree(mega_fit, metrum_fit) -> None:
    """The rocket carried both recorders: reconstructed apart, they give the same canopies
    within the fits' sigmas, which count the air's motion, combined in quadrature (at the
    two-sided 95 % level: |difference| < 1.96 sigma), and the same main fill constant."""
    (fa, ca), (fb, cb) = mega_fit, metrum_fit
    for name in ("CdS[drogue,stage1]", "CdS[main,stage2]", "n[main,stage2]"):
        combined = np.hypot(ca.std[name], cb.std[name])
        assert abs(fa.parameters[name] - fb.parameters[name]) < 1.96 * combined, name


def test_reconstruction_matches_the_descent(mega_fit) -> None:
    fit, cov = mega_fit
    # Every estimated quantity the card asks for has an uncertainty.
    for name in ("CdS[drogue,stage1]", "CdS[main,stage2]", "n[main,stage2]",
                 "t_start[main,stage2]", "bias[baro,altitude]", "lag[baro]"):
        assert name in fit.free
    assert "CdS[drogue,stage1]" in cov.std and "CdS[main,stage2]" in cov.std
    # The steady descent rates the fitted drag areas imply match the altimeter's within
    # their combined sigma (|z| < 3).
    rates = descent_rates(fit, cov)
    assert [r.canopies for r in rates] == [("drogue",), ("drogue", "main")]
    for r in rates:
        assert abs(r.z) < 3.0, r
    # The accelerometer's opening peak is the main's full-open time: the main starts after
    # its ejection charge and before that, off both bounds, so with a two-sided sigma; the
    # fill constant (expopen held at 1) is off its bounds too.
    charge = fit.test.event("mortar_fire", "main")
    full, full_sigma = _full_open(fit)
    assert charge.time < full < charge.time + OPENING_WINDOW_S
    start = "t_start[main,stage2]"
    assert start not in cov.at_bound and cov.std[start] > 0.0
    assert charge.time - charge.sigma < fit.parameters[start] < full
    n = fit.model.parameter("n[main,stage2]")
    assert "n[main,stage2]" not in cov.at_bound
    assert n.lower < fit.parameters["n[main,stage2]"] < n.upper
    assert cov.std["n[main,stage2]"] > 0.0
    # An opening's load peaks at or before full open (the riser's snatch mid-fill, or the
    # drag at full area): the model's fill ends no earlier than the peak, less its sigma.
    rise = fit.quantities()["rise_end[main,stage2]"][0]
    assert rise > full - full_sigma


def test_report_profiles_the_held_expopen(mega_still) -> None:
    """The card holds the main's expopen at 1: refitted with it held anywhere from 0.5 to 6,
    chi-square moves by less than the 95 % level once divided by chi2/dof, and the report
    says so, with the spread of n that holding it hides (in still air, where every point
    converges)."""
    fit, cov = mega_still
    held = held_opening_profiles(fit, spec_of_test(fit.test))
    prof = held["expopen[main,stage2]"]
    assert not prof.failures and prof.values.min() == 0.5 and prof.values.max() == 6.0
    scaled = (prof.delta_chi_square - prof.delta_chi_square.min()) / (fit.chi_square / fit.dof)
    assert np.all(scaled <= THRESHOLD)
    text = flight_text(fit, cov, load_card("prometheus").nominal, held=held)
    assert "expopen[main,stage2] is held at 1" in text
    assert "these data do not determine it" in text and "Over those values n[main,stage2]" in text


def test_nominal_drag_areas_are_compared(mega_fit) -> None:
    fit, cov = mega_fit
    card = load_card("prometheus")
    comps = nominal_comparisons(fit, cov, card.nominal, descent_rates(fit, cov))
    assert {c.name for c in comps} == set(card.nominal)
    for c in comps:
        # The rate the nominal drag area would give differs from the measured one in the
        # direction of the drag-area difference: more drag area, slower descent.
        assert np.sign(c.rate_nominal - c.rate_measured.measured) == np.sign(c.fitted - c.nominal)


def test_in_still_air_the_diagnosis_names_the_air_motion(mega_still) -> None:
    """In still air the altimeter and the GPS share the slow wander of their residuals in
    both canopy phases (the vehicle's altitude, not a sensor, departs from the model), and
    the evidence of a vertical wind process over still air is decisive."""
    fit, cov = mega_still
    common = common_residuals(fit)
    assert [c.channels for c in common] == [("baro altitude", "gps_altitude up")] * 2
    assert all(c.r > 0.7 for c in common)
    assert combined_p_value(common) < ALPHA
    air = wind_evidence(fit, without_wind(spec_of_test(fit.test), fit.test), ALPHA)
    assert air is not None and air.decisive and air.two_ln_b > DECISIVE_2LNB
    assert air.best_fit.chi_square / air.best_fit.dof < 1.5 < fit.chi_square / fit.dof
    assert "wind_process" in air.verdict()
    # The still-air report says what the fit's white-noise sigma leave out: the drag areas'
    # sigma from the measured rates exceed them, and the shared residual is named.
    text = flight_text(fit, cov, load_card("prometheus").nominal)
    assert "The altitude sensors share their residual" in text
    assert "vertical air motion" in text
    for c in nominal_comparisons(fit, cov, load_card("prometheus").nominal,
                                 descent_rates(fit, cov)):
        assert c.sigma_rate > 10.0 * c.sigma


def test_report_of_the_opening_and_of_what_remains(mega_fit) -> None:
    fit, cov = mega_fit
    text = flight_text(fit, cov, load_card("prometheus").nominal)
    assert "## Opening of the main" in text and "fill time" in text
    # Beside the accelerometer's samples the peak is not read as the fill's end.
    assert "riser's snatch" in text and "full open observed at" not in text
    assert "- the altitude sensors against each other:" in text
    assert "count the air's vertical motion" in text


def test_the_two_recorders_clocks_are_put_on_one_time_base() -> None:
    """Each recorder counts from its own boost detection: the offset measured on the motor's
    burn (100 Hz) is the one measured on the drogue's opening (10 Hz, within a sample),
    either way round, and larger than the boost's sample spacing."""
    mega, metrum = read_altus_log(DATA / MEGA).record(), read_altus_log(DATA / METRUM).record()
    boost = clock_offset(mega, metrum)
    assert abs(boost) > 0.02
    assert clock_offset(metrum, mega) == pytest.approx(-boost, abs=0.002)
    assert clock_offset(mega, metrum, window=(25.0, 35.0)) == pytest.approx(boost, abs=0.1)
