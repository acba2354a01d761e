"""A fit's progress on stderr: redrawn in place on a terminal, whole lines where stderr is
a pipe or a log file (so that a long solve run through a pipe is not silent), and nothing
without progress."""

from __future__ import annotations

import io
import re
import sys

import pytest

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


LINE = re.compile(r"^  iteration +(\d+) +chi-square +(\S+) +\((\d+) s\)$")


@pytest.fixture(scope="module")
def estimator(problem_folder) -> Estimator:
    return Estimator(load_test(problem_folder("rocket_steady", 1)))


def test_a_piped_fit_writes_whole_progress_lines(estimator, monkeypatch) -> None:
    """With stderr a pipe (not a terminal) and the line interval at zero, every iteration
    writes one whole line (no carriage returns) with its number, chi-square and the run's
    seconds; the numbers count up and the last chi-square is the fit's."""
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr("cpas_ocp.estimation.solve.PIPED_PROGRESS_S", 0.0)
    fit = estimator.solve(progress=True)
    text = err.getvalue()
    assert "\r" not in text
    lines = [LINE.match(line) for line in text.splitlines()]
    assert len(lines) >= 2 and all(lines)
    numbers = [int(m.group(1)) for m in lines]
    assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers)
    chi2 = [float(m.group(2)) for m in lines]
    assert chi2[-1] <= chi2[0]
    assert min(chi2) == pytest.approx(fit.chi_square, rel=0.05)


def test_piped_lines_are_spaced_by_the_interval(estimator, monkeypatch) -> None:
    """A fit shorter than the interval writes no line on a pipe: no flooding."""
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr("cpas_ocp.estimation.solve.PIPED_PROGRESS_S", 1e9)
    estimator.solve(progress=True)
    assert err.getvalue() == ""


def test_a_terminal_gets_one_line_redrawn_and_no_progress_gets_nothing(estimator,
                                                                      monkeypatch) -> None:
    for shown in (True, False):
        err = _Terminal()
        monkeypatch.setattr(sys, "stderr", err)
        estimator.solve(progress=shown)
        text = err.getvalue()
        if shown:
            assert text.startswith("\r  iteration") and text.endswith("\n")
            assert text.count("\n") == 1
        else:
            assert text == ""
