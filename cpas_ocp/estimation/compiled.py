"""Native code for the estimator's per-instance Jacobians, compiled once per model and cached.

CasADi evaluates SX functions in its virtual machine.  The same function
emitted as C and compiled by the system C compiler at -O1 (-O0 for very
large sources, and none above `VM_SOURCE_BYTES`) runs about four times faster on the
RK4-step Jacobians that dominate a reconstruction (and -O2 costs twice the
compile time for 10 % more).  The C source is hashed and
the shared library is kept under that hash in the cache folder
(``$CPAS_OCP_CACHE``, else ``~/.cache/cpas-ocp``), so a model structure is
compiled once per machine: every test folder with the same vehicle,
parachutes, sensors and atmosphere reuses it.

Compiled functions carry no derivatives; the estimator supplies every
derivative Ipopt needs (objective gradient, constraint Jacobian, Hessian)
from separately compiled Jacobian functions.  Without a C compiler, or with
``CPAS_OCP_COMPILE=0``, the SX functions are used unchanged.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca

from cpas_ocp import interrupts

FLAGS = ("-shared", "-fPIC")
# gcc's time and memory grow faster than the source, because CasADi emits each function
# as one body: a 4 MB Jacobian (a GPS model integrated back over its lag) took 400 s at
# -O1, and its 5.5 MB successor (`chained_jacobians.ModelPieces`: the lagged GPS output's
# Jacobian) 38 s and 8.0 GB at -O0 (`benchmarks/compile_cost.py`).  Sources above
# LARGE_SOURCE_BYTES are built at -O0, still about twice as fast as the virtual machine
# but three times slower than -O1; sources above VM_SOURCE_BYTES are not compiled at all
# and run in the virtual machine, which costs that one piece a factor of two or three
# and no minutes or gigabytes of compiling.  The pieces of the library's models are
# below 1.1 MB (the RK4 step's Jacobian of `drogue` with added mass) except that one.
LARGE_SOURCE_BYTES = 3_000_000
VM_SOURCE_BYTES = 4_000_000


def optimisation(source: Path) -> str:
    """-O1 for ordinary sources, -O0 for very large ones."""
    return "-O0" if source.stat().st_size > LARGE_SOURCE_BYTES else "-O1"

def cache_folder() -> Path:
    """Where compiled libraries are kept."""
    env = os.environ.get("CPAS_OCP_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "cpas-ocp"


def compiler() -> str | None:
    """The C compiler to use, or None when compiling is off or impossible."""
    if os.environ.get("CPAS_OCP_COMPILE", "1") == "0":
        return None
    return shutil.which("gcc") or shutil.which("cc")


def compile_functions(functions: list[ca.Function]) -> list[ca.Function]:
    """Native versions of `functions` (same names, inputs and outputs), compiled as needed.

    Missing libraries are compiled in parallel, one compiler per core at a
    time.  Falls back to the functions themselves when no compiler is
    available, or (with a warning on stderr) when the cache cannot be written
    or the compiler fails.
    """
    cc = compiler()
    if cc is None:
        return list(functions)
    try:
        return _compile(functions, cc)
    except (OSError, RuntimeError) as err:
        sys.stderr.write(f"warning: running the model in CasADi's VM, not native code: {err}\n")
        return list(functions)


def _compile(functions: list[ca.Function], cc: str) -> list[ca.Function]:
    folder = cache_folder()
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".cpas-cg-", dir=folder) as tmp, _live(Path(tmp)):
        sources = [_generate(fn, Path(tmp) / str(i)) for i, fn in enumerate(functions)]
        libraries = [folder / f"{fn.name()}-{_digest(src)}.so"
                     if src.stat().st_size <= VM_SOURCE_BYTES else None
                     for fn, src in zip(functions, sources, strict=True)]
        missing = [(src, lib) for src, lib in zip(sources, libraries, strict=True)
                   if lib is not None and not lib.exists()]
        if missing and sys.stderr.isatty():
            sys.stderr.write(f"  compiling {len(missing)} model functions to native code "
                             f"(once per model structure; cache {folder}) ...\n")
        jobs: list[tuple[subprocess.Popen, Path, Path]] = []
        # At most one compiler per core at a time, each started as one ends: a new model
        # structure on `drogue` (ten sources, the largest compiler 0.19 GB) held 0.53 GB of
        # compilers started all at once and 0.32 GB this way, in the same 14 s on 2 cores;
        # richer models' sources are larger and more.  Wait for every job before judging any,
        # so none is still writing into the temporary folder when a failure removes it.
        # Interrupted (Ctrl-C, SIGTERM, any error), every compiler is killed and waited for
        # before the temporary folder goes: each runs in a process group of its own (the
        # driver with its cc1 and as), killed whole, since killing the driver alone leaves
        # its cc1 running.
        try:
            for src, lib in missing:
                while sum(proc.poll() is None for proc, _, _ in jobs) >= _cores():
                    time.sleep(0.05)
                partial = src.parent / lib.name
                # A signal waits until the compiler is on the list of those to kill (one
                # raised inside Popen would leave it running, unlisted).
                with open(src.parent / "stderr", "wb") as err, interrupts.deferred():
                    jobs.append((subprocess.Popen([cc, optimisation(src), *FLAGS, "-o",
                                                   str(partial), str(src), "-lm"],
                                                  stdout=subprocess.DEVNULL, stderr=err,
                                                  start_new_session=True),
                                 partial, lib))
                    _LIVE.compilers.append(jobs[-1][0])
            for proc, _, _ in jobs:
                proc.wait()
        except BaseException:
            for proc, _, _ in jobs:
                _kill_group(proc)
            raise
        for proc, partial, lib in jobs:
            if proc.returncode != 0:
                err = (partial.parent / "stderr").read_bytes().decode(errors="replace")
                raise RuntimeError(f"compiling {lib.name} failed: {err[-500:]}")
            os.replace(partial, lib)  # atomic: a library in the cache is always complete
    return [fn if lib is None else ca.external(fn.name(), str(lib))
            for fn, lib in zip(functions, libraries, strict=True)]


@dataclass
class _Live:
    """The compilers running and the temporary folders they write in, for `abandon`."""

    compilers: list[subprocess.Popen] = field(default_factory=list)
    folders: list[Path] = field(default_factory=list)


_LIVE = _Live()


@contextmanager
def _live(folder: Path) -> Iterator[None]:
    """Register `folder` and the compilers started in it while the block runs."""
    _LIVE.folders.append(folder)
    try:
        yield
    finally:
        _LIVE.folders.remove(folder)
        _LIVE.compilers.clear()


def abandon() -> None:
    """Kill every running compiler and remove the temporary folders: for a process that
    must end at once, without unwinding (a local worker of a campaign told to stop)."""
    for proc in _LIVE.compilers:
        _kill_group(proc)
    for folder in _LIVE.folders:
        shutil.rmtree(folder, ignore_errors=True)


def _kill_group(proc: subprocess.Popen) -> None:
    """Kill the process group `proc` leads (a compiler driver and the passes it started),
    and wait for the driver; the group's other members, orphaned, are reaped by init."""
    with suppress(ProcessLookupError):  # the whole group has already ended
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() or 1


def _generate(fn: ca.Function, folder: Path) -> Path:
    folder.mkdir()
    name = f"{fn.name()}.c"
    gen = ca.CodeGenerator(name, {"with_header": False})
    gen.add(fn)
    gen.generate(str(folder) + os.sep)
    return folder / name


def _digest(source: Path) -> str:
    h = hashlib.sha256(source.read_bytes())
    h.update(" ".join([optimisation(source), *FLAGS]).encode())
    h.update(ca.__version__.encode())
    return h.hexdigest()[:20]
