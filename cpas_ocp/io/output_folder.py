"""Output folders written all at once: a reader sees the old folder or the new one, never half.

The output is written into a hidden sibling `.cpas-out-<pid>-*` and renamed
into place at the end; the sibling is removed on every exit path Python
sees (errors, Ctrl-C, SIGTERM through `interrupts`).  A process killed
outright (SIGKILL, power loss) leaves its sibling behind: the next run in the
same folder removes those whose process is gone.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from cpas_ocp.errors import InputError


@contextmanager
def atomic_folder(out: str | Path, marker: str | tuple[str, ...]) -> Iterator[Path]:
    """Yield a temporary folder beside `out`; on success it takes `out`'s place in one step
    (`_exchange`).

    `out` must be new, empty, or an earlier output of the same kind (it holds
    `marker`, or one of several), so a mistyped path never deletes a user's
    data.  On any error the temporary folder is removed and `out` is left as
    it was.
    """
    out = Path(out)
    markers = (marker,) if isinstance(marker, str) else marker
    check_output(out)
    if out.exists() and any(out.iterdir()) and not any((out / m).exists() for m in markers):
        raise InputError(str(out), "(folder)", f"a new or empty folder, or an earlier output "
                         f"folder (holding {' or '.join(markers)}) to replace")
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_orphans(out.parent)
    tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-", dir=out.parent))
    try:
        yield tmp
        if not out.exists():
            tmp.rename(out)
        elif not _exchange(tmp, out):
            shutil.rmtree(out)
            tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)  # after an exchange, the earlier output


def _exchange(a: Path, b: Path) -> bool:
    """Swap two folders in one step (Linux's renameat2 with RENAME_EXCHANGE), so that a
    process killed at any moment leaves one of them whole under `b`'s name; False where
    the system cannot (the caller then removes `b` and renames `a`)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_cwd, exchange = -100, 2  # AT_FDCWD, RENAME_EXCHANGE
    return renameat2(at_cwd, os.fsencode(a), at_cwd, os.fsencode(b), exchange) == 0


TMP_PREFIX = ".cpas-out-"


def check_output(out: Path) -> None:
    """InputError unless `out` can become an output folder: not a file or a symbolic link
    (a link's target would be replaced, or a dangling one written through), and under
    a folder this user may create folders in (tried: permissions alone do not tell, in
    /proc or on a read-only file system).  Run before the work, so a mistyped `--out`
    fails in a second rather than after the solve."""
    try:
        _check_output(out)
    except OSError as exc:  # a name too long, a folder that may not be read, ...
        raise InputError(str(out), "(folder)", f"a folder path this user may create; "
                         f"{exc.strerror or exc}") from None


def _check_output(out: Path) -> None:
    if out.is_symlink():
        raise InputError(str(out), "(folder)", "a folder path, not a symbolic link (give the "
                         "link's target, or a new path)")
    if out.exists() and not out.is_dir():
        raise InputError(str(out), "(folder)", "a folder; a file of that name exists")
    ancestor = out.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(str(out), "(folder)", f"a path under folders; {ancestor} is a file")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(str(out), "(folder)", f"a place this user may write; {ancestor} "
                         "is not writable")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-", dir=ancestor))
    except OSError as exc:
        raise InputError(str(out), "(folder)", f"a place this user may create folders in; "
                         f"{ancestor}: {exc.strerror or exc}") from None


def sweep_orphans(folder: Path) -> None:
    """Remove temporary output folders in `folder` whose writing process no longer runs."""
    for tmp in folder.glob(f"{TMP_PREFIX}*"):
        pid = tmp.name[len(TMP_PREFIX):].split("-", 1)[0]
        if tmp.is_dir() and pid.isdigit() and not _running(int(pid)):
            shutil.rmtree(tmp, ignore_errors=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True
