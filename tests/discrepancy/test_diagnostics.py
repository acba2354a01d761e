"""Where the model fails: phase windows, per-window residual statistics, the diagnosis of
each channel and window, and the residual figures.

Every test reuses the session fits of `fbcp` and `drogue` seed 1; errors are
injected into copies of their residuals (`dataclasses.replace`), in units of
each sample's sigma, so what must be found is known:

* a Hann bump of 3 sigma peak over the ~55 samples of an inflation window adds
  about 9 x 0.375 x 55 = 190 to that window's chi-square, where the noise
  spreads a window's chi^2 - n by sqrt(2 n), 10-70 for the windows here: the
  worst place must be that window;
* a 5 Hz sinusoid of 0.5 sigma over the 590 samples of a steady window puts
  590 x 0.25 / 4 = 37 into one periodogram ordinate against a mean of 1 over
  295: Fisher's g p-value near 1e-13, far beyond any Holm threshold (about
  alpha / 300); the frequency comes within one bin, rate / n = 0.34 Hz;
* white noise in place of every channel's residual: Holm's correction keeps
  the chance of any significant finding below alpha = 0.05 per series, so
  over 20 seeded series the count of series with one lies within the
  binomial(20, 0.05) 0.999 quantile.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom

from cpas_ocp.discrepancy.residual_diagnosis import (
    LAG,
    PERIODICITY,
    WHOLE_PHASE,
    Finding,
    diagnose_residuals,
    plausible_lag,
    signature_text,
)
from cpas_ocp.estimation.estimator import Fit, Settings, SolverStats
from cpas_ocp.estimation.simulate import initial_state, simulate
from cpas_ocp.inference.diagnostics import (
    WindowStatistic,
    window_statistics,
    worst_of,
    worst_place,
)
from cpas_ocp.inference.phase_windows import (
    OUTSIDE,
    PhaseWindow,
    phase_windows,
    window_index,
)
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.problems import load_problem, problem_names
from cpas_ocp.physics.parameters import param_name
from cpas_ocp.reports.plots import plot_sensor_residuals

pytestmark = pytest.mark.slow

TRUTH_STEP_S = 0.01  # RK4 step of the truth trajectories: fine for drag areas over 0.1 s fills


def _by_canopy(windows: list[PhaseWindow]) -> dict[str, list[PhaseWindow]]:
    out: dict[str, list[PhaseWindow]] = {}
    for w in windows:
        out.setdefault(w.parachute, []).append(w)
    return out


def _assert_well_formed(fit: Fit, windows: list[PhaseWindow]) -> None:
    """Inside the data, non-empty, known kinds, and per canopy ordered without overlap."""
    for w in windows:
        assert fit.t[0] <= w.t0 < w.t1 <= fit.t[-1], w
        assert w.kind in ("deployment", "inflation", "steady"), w
    for chute, ws in _by_canopy(windows).items():
        for a, b in itertools.pairwise(ws):
            assert a.t1 <= b.t0 + 1e-12, (chute, a, b)


def test_drogue_windows_follow_the_fitted_stages(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    windows = phase_windows(fit)
    _assert_well_formed(fit, windows)
    q = fit.quantities()
    h = float(fit.t[1] - fit.t[0])
    names = [w.name for w in windows]
    assert len(names) == len(set(names))
    for chute in fit.test.parachutes:
        ws = _by_canopy(windows)[chute.name]
        mortar = fit.test.event("mortar_fire", chute.name)
        assert ws[0].name == f"deployment {chute.name}"
        assert ws[0].t0 == pytest.approx(mortar.time)
        cds = q[param_name("cds", chute.name)]
        starts = [fit.parameters[param_name("t_start", chute.name, s)] for s in chute.stages]
        for k, stage in enumerate(chute.stages):
            (infl,) = [w for w in ws if w.kind == "inflation" and w.stage == stage]
            assert infl.name == f"inflation {chute.name} {stage}"
            assert infl.t0 == pytest.approx(starts[k], abs=1e-12)
            nxt = starts[k + 1] if k + 1 < len(starts) else fit.t[-1]
            span = (fit.t >= starts[k]) & (fit.t < nxt)
            t_peak = fit.t[span][np.argmax(cds[span])]
            # Ends after the over-inflation peak, and by the end of the Eq. 6 settling.
            assert infl.t1 > t_peak
            t_k = fit.parameters[param_name("t_k", chute.name, stage)]
            assert infl.t1 <= t_peak + t_k + 2 * h
            (steady,) = [w for w in ws if w.kind == "steady" and w.stage == stage]
            assert steady.t0 == infl.t1
            assert steady.t1 == pytest.approx(nxt, abs=1e-12)
            # Settled: within 2 % of the stage's steady drag area through the steady window.
            inside = (fit.t >= steady.t0) & (fit.t < steady.t1)
            steady_cds = fit.parameters[param_name("CdS", chute.name, stage)]
            assert np.max(np.abs(cds[inside] / steady_cds - 1)) <= 0.02


def _truth_fit(folder: Path, problem: str) -> Fit:
    """The problem's truth as a fit: the manifest's model along a trajectory simulated
    with the true parameters (no residuals)."""
    test = load_test(folder)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    model = spec_of_test(test).model(test)
    x0 = initial_state(model, load_problem(problem).simulation)
    traj = simulate(model, truth, x0, test.t_start, test.t_end, step=TRUTH_STEP_S)
    return Fit(test, model, truth, [], {}, traj.t, traj.x, traj.captures, [],
               SolverStats("truth", True, 0, 0.0, 0.0), Settings())


@pytest.mark.parametrize("problem", problem_names())
def test_every_problem_has_well_formed_windows(problem_folder, problem: str) -> None:
    fit = _truth_fit(problem_folder(problem, 1), problem)
    windows = phase_windows(fit)
    _assert_well_formed(fit, windows)
    for chute in fit.test.parachutes:
        ws = _by_canopy(windows)[chute.name]
        inflating = [] if chute.open_at_start else list(chute.stages)
        assert [w.stage for w in ws if w.kind == "inflation"] == inflating
    # Without observed events deployment runs from the start of the data; a canopy
    # without stages has no windows; neither is an error.
    bare = replace(fit.test, events=(),
                   parachutes=(replace(fit.test.parachutes[0], stages=()),
                               *fit.test.parachutes[1:]))
    windows = phase_windows(replace(fit, test=bare))
    _assert_well_formed(fit, windows)
    assert not [w for w in windows if w.parachute == fit.test.parachutes[0].name]
    for w in windows:
        if w.kind == "deployment":
            assert w.t0 == fit.t[0]


@pytest.mark.parametrize("problem", ["fbcp", "drogue"])
def test_window_chi_squares_add_up_to_each_channel(problem_fit, problem: str) -> None:
    fit, _, _ = problem_fit(problem, 1)
    windows = phase_windows(fit)
    stats = window_statistics(fit, windows)
    names = {w.name for w in windows} | {OUTSIDE}
    for r in fit.residuals:
        mine = [s for s in stats if (s.sensor, s.channel) == (r.sensor, r.channel)]
        assert {s.window for s in mine} <= names
        assert sum(s.samples for s in mine) == r.t.size
        chi2 = float(np.sum(r.normalised**2))
        assert sum(s.chi_square for s in mine) == pytest.approx(chi2, rel=1e-12)
        assert sum(s.fraction for s in mine) == pytest.approx(chi2 / fit.chi_square, rel=1e-12)
        by_name = {w.name: w for w in windows}
        for s in mine:
            assert s.normalised_rms == pytest.approx(np.sqrt(s.chi_square / s.samples))
            # The statistic spans the samples it counts, inside its window's bounds.
            assert s.t0 <= s.t1 and {s.t0, s.t1} <= set(r.t)
            if s.window != OUTSIDE:
                assert by_name[s.window].t0 <= s.t0 and s.t1 <= by_name[s.window].t1
    # A load cell sees its own canopy's windows only.
    own = {w.name for w in windows if w.parachute == "fbcp1" or w.parachute == "drogue1"}
    riser = [s for s in stats if s.sensor.startswith("riser_") and s.sensor.endswith("1")]
    assert riser and {s.window for s in riser} <= own | {OUTSIDE}


def _inject(fit: Fit, sensor: str, window: PhaseWindow, shape) -> Fit:
    """A copy of `fit` with `shape(t, window)` sigmas added to one channel's measurements
    inside `window`."""
    residuals = []
    for r in fit.residuals:
        if r.sensor == sensor:
            inside = window.contains(r.t)
            r = replace(r, measured=r.measured + np.where(inside, r.sigma * shape(r.t), 0.0))
        residuals.append(r)
    return replace(fit, residuals=residuals)


def test_worst_place_names_an_injected_bump(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    windows = phase_windows(fit)
    target = next(w for w in windows if w.name == "inflation drogue1 stage2")

    def bump(t: np.ndarray) -> np.ndarray:  # Hann bump of 3 sigma peak over the window
        return 3.0 * np.sin(np.pi * (t - target.t0) / (target.t1 - target.t0)) ** 2

    clean = worst_place(fit, windows)
    line = worst_place(_inject(fit, "riser_drogue1", target, bump), windows)
    assert line.startswith("riser_drogue1 tension, inflation drogue1 stage2 (")
    assert line != clean
    assert "\n" not in line and "% of the total chi-square" in line


def test_a_clean_fit_shows_no_significant_finding(problem_fit) -> None:
    fit, _, _ = problem_fit("fbcp", 1)
    findings = diagnose_residuals(fit, phase_windows(fit))
    assert findings
    assert not [str(f) for f in findings if f.significant]
    assert signature_text(findings).startswith("No residual signature beyond the noise")
    assert all("consistent with white noise" in str(f) for f in findings)


def test_an_injected_oscillation_is_found_where_and_at_what_frequency(problem_fit) -> None:
    fit, _, _ = problem_fit("fbcp", 1)
    windows = phase_windows(fit)
    target = next(w for w in windows if w.name == "steady fbcp1 stage1")
    hurt = _inject(fit, "riser_fbcp1", target,
                   lambda t: 0.5 * np.sin(2 * np.pi * 5.0 * t + 0.3))
    findings = diagnose_residuals(hurt, windows)
    top = findings[0]
    assert (top.sensor, top.channel, top.window) == ("riser_fbcp1", "tension", target.name)
    assert top.significant and PERIODICITY in top.rejected
    rate = 1.0 / np.median(np.diff(fit.residuals[-2].t))
    assert abs(top.frequency_hz - 5.0) <= rate / top.samples
    assert [f for f in findings if f.significant] == [top]
    assert "Hz line" in str(top)
    text = signature_text(findings)
    assert "riser_fbcp1 tension, window steady fbcp1 stage1" in text
    assert "periodic at 5." in text


def test_white_noise_rarely_gives_a_significant_finding(problem_fit) -> None:
    fit, _, _ = problem_fit("fbcp", 1)
    windows = phase_windows(fit)
    alpha, series = 0.05, 20
    hit = 0
    for seed in range(series):
        rng = np.random.default_rng(seed)
        noise = [replace(r, measured=r.model + r.sigma * rng.standard_normal(r.t.size))
                 for r in fit.residuals]
        findings = diagnose_residuals(replace(fit, residuals=noise), windows, alpha=alpha)
        hit += any(f.significant for f in findings)
    assert hit <= binom.ppf(0.999, series, alpha), hit


def test_channels_cut_too_short_are_also_tested_whole(problem_fit) -> None:
    """Half-second windows leave 10 Hz GPS with 5 samples each: tested as a whole; the
    200 Hz channels are tested per window."""
    fit, _, _ = problem_fit("fbcp", 1)
    windows = [PhaseWindow(f"steady w{k}", "steady", "fbcp1", "stage1", 0.5 * k, 0.5 * k + 0.5)
               for k in range(8)]
    findings = diagnose_residuals(fit, windows)
    whole = {(f.sensor, f.channel) for f in findings if f.window == WHOLE_PHASE}
    assert whole == {(r.sensor, r.channel) for r in fit.residuals if r.sensor == "gps"}
    imu = [f for f in findings if f.sensor == "imu"]
    assert sorted(f.window for f in imu) == sorted(w.name for w in windows)
    assert all(abs(f.samples - 100) <= 1 for f in imu)


def test_window_index_prefers_inflation_then_the_latest_start() -> None:
    ws = [PhaseWindow("steady a", "steady", "a", "s1", 0.0, 4.0),
          PhaseWindow("inflation b", "inflation", "b", "s1", 1.0, 2.0),
          PhaseWindow("steady b", "steady", "b", "s1", 2.0, 4.0),
          PhaseWindow("deployment b", "deployment", "b", None, 0.5, 1.0)]
    t = np.array([0.2, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0])
    assert list(window_index(t, ws)) == [0, 3, 1, 1, 1, 2, -1]


def test_one_residual_figure_per_sensor(problem_fit, tmp_path: Path) -> None:
    fit, _, _ = problem_fit("fbcp", 1)
    paths = plot_sensor_residuals(fit, phase_windows(fit), tmp_path)
    sensors = list(dict.fromkeys(r.sensor for r in fit.residuals))
    assert [p.name for p in paths] == [f"residuals_{s}.png" for s in sensors]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(tmp_path.iterdir()) == sorted(paths)


@pytest.mark.parametrize("lag_s, window_s, plausible", [
    (0.25, 10.0, True),  # a GPS's quarter-second report delay
    (-0.06, 10.0, False),  # a GPS reporting before the event
    (2.6, 60.0, False),  # beyond a second
    (0.8, 5.0, False),  # more than a tenth of the window
])
def test_a_lag_is_called_one_only_where_a_sensor_could_have_it(lag_s: float, window_s: float,
                                                               plausible: bool) -> None:
    finding = Finding("gps", "up", "steady", 10.0, 10.0 + window_s, 200, 3.0, 1e-9, 1.0,
                      0.5, lag_s, 0.01, 1e-12, rejected=(LAG,), significant=True)
    assert plausible_lag(finding) is plausible
    line = str(finding)
    assert ("lag of" in line) is plausible
    assert ("not as a sensor lag" in line) is not plausible
    assert f"{1e3 * lag_s:+.1f}" in line


def test_a_window_of_too_few_samples_is_not_the_worst_fit() -> None:
    """One sample 20 sigma off in a one-sample window holds more excess (399) than a
    600-sample window at normalised RMS 1.2 (264), but cannot be told from an outlier
    (`MIN_RANKED_SAMPLES`):
    the long window is the worst fit, and with no other window the short one is."""
    one = WindowStatistic("gps", "up", "deployment", 0.0, 0.0, 1, 20.0, 20.0, 400.0, 0.2)
    long = WindowStatistic("gps", "up", "steady", 1.0, 7.0, 600, 1.2, 1.2, 864.0, 0.4)
    assert worst_of([one, long]).startswith("gps up, steady")
    assert worst_of([one]).startswith("gps up, deployment")
