"""The progress line: drawn on a terminal with what, how far and the detail; nothing at all
where stderr is not a terminal or the caller turned it off."""

from __future__ import annotations

import io
import sys

import pytest

from cpas_ocp.progress import progress_line


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _run(enabled: bool) -> None:
    with progress_line("score tests", 3, enabled) as advance:
        for name in ("added_mass", "gps_lag", "elastic_riser"):
            advance(name)


def test_on_a_terminal_the_line_says_what_how_far_and_the_last_item(monkeypatch) -> None:
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    _run(enabled=True)
    shown = err.getvalue()
    assert "score tests" in shown
    assert "3/3" in shown
    assert "elastic_riser" in shown


@pytest.mark.parametrize(("stream", "enabled"), [(io.StringIO, True), (_Terminal, False)])
def test_off_a_terminal_or_turned_off_nothing_is_written(monkeypatch, stream, enabled) -> None:
    err = stream()
    monkeypatch.setattr(sys, "stderr", err)
    _run(enabled)
    assert err.getvalue() == ""
