"""Progress of long work on the terminal: what is under way, how far, for how long.

One line on stderr, drawn by `rich` (counts, a bar, the elapsed time), and
nothing at all where stderr is not a terminal (a log file, a pipe, a test),
so a program reading the output never sees it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

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
