"""Two recorders' clocks put on one time base (`cpas_ocp.io.recorder_clocks`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.io.flight_record import FlightRecord, samples_frame
from cpas_ocp.io.recorder_clocks import RecorderEstimates, clock_offset
from cpas_ocp.reports.import_text import recorders_text

SHIFT_S = 0.037  # the second recorder's clock reads this much more for the same instant
NOISE = 0.5  # accelerometer noise (m/s^2), as an Altus Metrum reads on the pad


def _thrust(t: np.ndarray) -> np.ndarray:
    """A motor's axial acceleration (m/s^2): lit at 0, a 0.3 s rise, 4 s burn, burnout."""
    return np.where((t > 0.0) & (t < 4.0), 80.0 * (1.0 - np.exp(-t / 0.1)) * (1.0 + 0.1 * t),
                    np.where(t >= 4.0, -9.0, 0.0))


def _log(name: str, clock_shift: float, seed: int) -> FlightRecord:
    """A 100 Hz log of the thrust curve on a clock that reads `clock_shift` more."""
    rng = np.random.default_rng(seed)
    t_true = np.arange(-1.0, 7.0, 0.01) + rng.uniform(0.0, 0.01)
    data = samples_frame(t_true + clock_shift, 86000.0 - 10.0 * np.arange(t_true.size),
                         _thrust(t_true) + NOISE * rng.normal(size=t_true.size))
    return FlightRecord(Path(name), "TeleMetrum", data)


def test_a_known_shift_between_two_noisy_clocks_is_recovered() -> None:
    a, b = _log("a.csv", 0.0, 1), _log("b.csv", SHIFT_S, 2)
    assert clock_offset(a, b) == pytest.approx(SHIFT_S, abs=0.003)
    assert clock_offset(b, a) == pytest.approx(-SHIFT_S, abs=0.003)


def test_a_window_without_samples_is_refused_naming_the_log() -> None:
    """A second log whose clock lies 50 s away has nothing in the window to align by."""
    a, far = _log("a.csv", 0.0, 1), _log("b.csv", 50.0, 2)
    with pytest.raises(ValueError, match=r"b\.csv: fewer than ten accelerometer samples"):
        clock_offset(a, far, window=(3.0, 5.0), search_s=0.1)


def test_the_recorders_table_puts_start_times_on_the_first_clock() -> None:
    """b's start time, read on its clock, is moved onto a's before the difference is taken;
    drag areas are compared as they are."""
    a, b = _log("a.csv", 0.0, 1), _log("b.csv", SHIFT_S, 2)
    shift = clock_offset(a, b)
    text = recorders_text([
        RecorderEstimates(a, {"CdS[main]": (5.0, 0.3), "t_start[main]": (100.0, 0.05)}),
        RecorderEstimates(b, {"CdS[main]": (5.6, 0.4), "t_start[main]": (100.1 + shift, 0.05)})])
    rows = {line.split(" | ")[0].strip("| "): line for line in text.splitlines()
            if line.startswith("| ") and "parameter" not in line}
    assert "100.100 ± 0.050" in rows["t_start[main]"]
    assert rows["t_start[main]"].endswith(f"| {0.1 / np.hypot(0.05, 0.05):+.1f} |")
    assert rows["CdS[main]"].endswith(f"| {0.6 / 0.5:+.1f} |")
    assert f"b.csv reads {shift:+.3f} s against a.csv" in text
