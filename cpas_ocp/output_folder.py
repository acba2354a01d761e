"""Output folders written all at once: a reader sees the old folder or the new one, never half."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError


@contextmanager
def atomic_folder(out: str | Path, marker: str | tuple[str, ...]) -> Iterator[Path]:
    """Yield a temporary folder beside `out`; on success it replaces `out` in one rename.

    `out` must be new, empty, or an earlier output of the same kind (it holds
    `marker`, or one of several), so a mistyped path never deletes a user's
    data.  On any error the temporary folder is removed and `out` is left as
    it was.
    """
    out = Path(out)
    markers = (marker,) if isinstance(marker, str) else marker
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not any(
            (out / m).exists() for m in markers))):
        raise InputError(str(out), "(folder)", f"a new or empty folder, or an earlier output "
                         f"folder (holding {' or '.join(markers)}) to replace")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".cpas-out-", dir=out.parent))
    try:
        yield tmp
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
