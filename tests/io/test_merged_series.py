"""A long log's independent samples merged into means where the signal is straight
(`log_noise.merged_blocks`, the import's `merged_series` step): no information lost on a
steady descent, an opening's samples kept, gaps never spanned, and each mean weighed at
the sigma of a mean of its samples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io import flight_log
from cpas_ocp.io.example_flight import fly
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.import_steps import STEPS, merged_series
from cpas_ocp.io.log_noise import CURVATURE_BIAS, MERGE_SPAN_S, merged_blocks
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped

RATE_HZ = 100.0
SIGMA = 0.3  # white noise of the synthetic channel (m)


def _descent(t: np.ndarray) -> np.ndarray:
    """Altitude (m) of a descent slowing as the air thickens: 1500 m at 7 m/s, gently
    curved (a few cm/s^2)."""
    return 1500.0 - 7.0 * t + 0.002 * t**2


def _weighted_line_fit(t: np.ndarray, y: np.ndarray, sigma: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares quadratic: the coefficients and their sigmas."""
    a = np.vander(t, 3) / sigma[:, None]
    cov = np.linalg.inv(a.T @ a)
    return cov @ a.T @ (y / sigma), np.sqrt(np.diag(cov))


def test_a_steady_descent_merges_without_losing_its_information() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 300.0, 1.0 / RATE_HZ)
    y = _descent(t) + rng.normal(0.0, SIGMA, t.size)
    mt, my, count = merged_blocks(t, y, SIGMA)
    assert t.size / mt.size >= 16  # a 100 Hz channel merges to a few hertz
    assert np.all(np.diff(mt) > 0) and count.sum() == t.size
    assert np.all(count * (1.0 / RATE_HZ) <= MERGE_SPAN_S + 1e-9)
    raw, raw_sigma = _weighted_line_fit(t, y, np.full(t.size, SIGMA))
    merged, merged_sigma = _weighted_line_fit(mt, my, SIGMA / np.sqrt(count))
    # The same estimates to a small share of their sigma, and the same sigmas: the means
    # carry what the samples carried.
    assert np.all(np.abs(merged - raw) < 0.05 * raw_sigma)
    np.testing.assert_allclose(merged_sigma, raw_sigma, rtol=0.02)


def test_an_opening_keeps_its_samples_and_no_mean_is_biased_beyond_the_rule() -> None:
    """An opening's deceleration (a rocket's speed from 40 to 7 m/s with a 0.7 s time
    constant at 60 s): the means there are short, and every mean, noise-free, lies within
    about CURVATURE_BIAS of its own sigma of the signal at its mean time."""
    t = np.arange(0.0, 120.0, 1.0 / RATE_HZ)
    tau = 0.7
    s = np.clip(t - 60.0, 0.0, None)
    truth = 3000.0 - 40.0 * np.minimum(t, 60.0) - 7.0 * s - 33.0 * tau * (1 - np.exp(-s / tau))
    noisy = truth + np.random.default_rng(5).normal(0.0, SIGMA, t.size)
    mt, _, count = merged_blocks(t, noisy, SIGMA)
    near = np.abs(mt - 60.2) < 0.5
    far = np.abs(mt - 60.0) > 10.0
    assert count[near].max() <= np.median(count[far]) / 4
    first = np.r_[0, np.cumsum(count)[:-1]]
    means = np.add.reduceat(truth, first) / count
    bias = np.abs(means - np.interp(mt, t, truth)) / (SIGMA / np.sqrt(count))
    assert bias.max() <= 2.0 * CURVATURE_BIAS


def test_a_gap_is_never_spanned() -> None:
    t = np.arange(0.0, 20.0, 1.0 / RATE_HZ)
    t = t[(t < 8.0) | (t > 8.5)]  # a charge's window left out
    y = _descent(t) + np.random.default_rng(6).normal(0.0, SIGMA, t.size)
    _, _, count = merged_blocks(t, y, SIGMA)
    first = np.r_[0, np.cumsum(count)[:-1]]
    last = first + count - 1
    assert not np.any((t[first] < 8.0) & (t[last] > 8.5))
    assert count.sum() == t.size


def test_the_import_weighs_each_mean_as_its_samples(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """The folder's altimeter and accelerometer carry the information of the samples they
    merged: the sum of 1/sigma^2 over the written rows (the manifest's sigma and its
    changes, as the fit reads them) is that of the rows the import wrote before merging
    (white noise: no sample counted twice, none lost)."""
    log, card, columns = tmp_path / "log.csv", tmp_path / "card.json", tmp_path / "map.json"
    write_mapped(fly(), log, seed=7)
    card.write_text(json.dumps(CARD))
    columns.write_text(json.dumps(COLUMN_MAP))
    args = ["import", str(log), "--columns", str(columns), "--card", str(card), "--out"]
    assert main([*args, str(tmp_path / "merged")]) == 0
    monkeypatch.setattr(flight_log, "STEPS", tuple(s for s in STEPS if s is not merged_series))
    assert main([*args, str(tmp_path / "raw")]) == 0
    merged, raw = load_test(tmp_path / "merged"), load_test(tmp_path / "raw")
    notes = json.loads((tmp_path / "merged" / "import.json").read_text())["notes"]
    assert any("merged into" in n for n in notes)
    for kind in ("baro", "axial_accelerometer"):
        (m,) = [s for s in merged.sensors if s.kind == kind]
        (r,) = [s for s in raw.sensors if s.kind == kind]
        assert len(m.data) < 0.25 * len(r.data)
        info_m = np.sum(m.absolute_sigma(m.channels[0]) ** -2.0)
        info_r = np.sum(r.absolute_sigma(r.channels[0]) ** -2.0)
        # Never more information than the samples (the sigmas are written to four
        # significant digits); less only where a later opening's raw samples, under 1 % of
        # the channel's information here, read the opening's dynamics as correlation.
        assert info_r * (1 - 0.01) <= info_m <= info_r * (1 + 2e-3)
