"""Progress of long work on the terminal: what is under way, how far, for how long.

One line on stderr, drawn by `rich` (counts, a bar, the elapsed time), and
nothing at all where stderr is not a terminal (a log file, a pipe, a test),
so a program reading the output never sees it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn


@contextmanager
def progress_line(what: str, total: int, enabled: bool = True
                  ) -> Iterator[Callable[..., None]]:
    """A progress line for `total` items of `what` ("score tests"); yields
    `advance(detail="", done=1)`, to call as each item ends (`detail`: the next one's name
    or a count).  Quiet unless `enabled` and stderr is a terminal."""
    if not (enabled and sys.stderr.isatty()):
        yield lambda detail="", done=1: None
        return
    columns = (TextColumn("  {task.description}"), BarColumn(bar_width=24),
               MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("{task.fields[detail]}"))
    with Progress(*columns, console=Console(stderr=True), transient=False) as bar:
        task = bar.add_task(what, total=total, detail="")

        def advance(detail: str = "", done: int = 1) -> None:
            bar.update(task, advance=done, detail=detail)

        yield advance


def _quiet(_line: str) -> None:
    """Say nothing."""


@dataclass(frozen=True)
class Narration:
    """Where a workflow says what it is doing and what its user should know.

    say: a step under way or done ("solving: ..."), stdout on the command line;
    warn: what the result's reader must know (an undetermined combination, a
    sensor no effect predicts), stderr on the command line;
    progress: whether long loops draw a progress line (`progress_line`).
    Silent by default, as a notebook or a script wants it."""

    say: Callable[[str], None] = _quiet
    warn: Callable[[str], None] = _quiet
    progress: bool = False


SILENT = Narration()


def terminal(progress: bool = True) -> Narration:
    """Narration on the terminal: steps on stdout (flushed, so they show before the work),
    warnings on stderr prefixed "warning: ", progress lines where `progress`."""
    return Narration(lambda line: print(line, flush=True),
                     lambda line: print(f"warning: {line}", file=sys.stderr, flush=True),
                     progress)
