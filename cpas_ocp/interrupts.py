"""SIGINT and SIGTERM as an orderly stop: no half-written output, no solver failure reported.

The command line installs `handle_signals`: a signal then raises `Interrupted`,
which unwinds every `finally` (temporary output folders are removed, compiler
children killed) and ends the process with 128 + the signal's number (130
for Ctrl-C, 143 for SIGTERM).  Inside Ipopt the Python stack is not running,
and an exception raised in one of its callbacks is reported by CasADi as the
solver's own failure (`User_Requested_Stop`), which a campaign or a retry
script would read as non-convergence.  So a solve runs in `deferred()`: there
a signal only marks itself `pending()`; the solver's iteration callback stops
the run at its next iteration, and `deferred` raises `Interrupted` once the
solver has returned.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(BaseException):
    """The user or the system asked the process to stop (a BaseException, like
    KeyboardInterrupt, so that no `except Exception` swallows it)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


class _Signals:
    """The process's signal state (a plain class: the command line imports this module
    before its handlers are in place, so it imports as little as it can)."""

    def __init__(self) -> None:
        self.depth = 0  # nested `deferred` regions entered
        self.pending: int | None = None  # the signal that arrived inside one
        self.received: int | None = None  # the last signal this process was asked to stop by


_state = _Signals()


def _handler(signum: int, frame: FrameType | None) -> None:
    _state.received = signum
    if _state.depth:
        _state.pending = signum
        return
    raise Interrupted(signum)


def handle_signals() -> None:
    """Turn SIGINT and SIGTERM into `Interrupted` (call from the main thread)."""
    for sig in SIGNALS:
        signal.signal(sig, _handler)


def received() -> bool:
    """Whether the process has been asked to stop by a signal (its work is to be dropped,
    not finished in the background)."""
    return _state.received is not None


def pending() -> bool:
    """Whether a signal arrived inside `deferred` and awaits its end."""
    return _state.pending is not None


@contextmanager
def deferred() -> Iterator[None]:
    """A region in which a signal only marks itself pending; on leaving it, a pending
    signal raises `Interrupted`.  Without `handle_signals` installed, signals keep
    their default behaviour."""
    _state.depth += 1
    try:
        yield
    finally:
        _state.depth -= 1
        signum = _state.pending
        if signum is not None and not _state.depth:
            _state.pending = None
            raise Interrupted(signum)
