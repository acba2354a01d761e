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

import atexit
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import suppress
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
# Builds that had a library to compile, and compilers started, in this process (benchmarks).
COUNTS = {"builds": 0, "libraries": 0}
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


def in_background() -> bool:
    """Whether a model met for the first time runs in the VM while its native code compiles
    (the default), rather than waiting for it (``CPAS_OCP_COMPILE=wait``)."""
    return os.environ.get("CPAS_OCP_COMPILE", "1") != "wait"


def compile_functions(functions: list[ca.Function]) -> list[ca.Function]:
    """Native versions of `functions` (same names, inputs and outputs), compiled as needed
    and waited for.

    Missing libraries are compiled in parallel, one compiler per core at a
    time.  Falls back to the functions themselves when no compiler is
    available, or (with a warning on stderr) when the cache cannot be written
    or the compiler fails.
    """
    build = native_build(functions)
    return list(functions) if build is None else build.wait()


def native_build(functions: list[ca.Function]) -> NativeBuild | None:
    """The native versions of `functions` under way (`NativeBuild`), or None where there is
    no compiler or the cache cannot be written (with a warning)."""
    cc = compiler()
    if cc is None:
        return None
    try:
        return NativeBuild(functions, cc)
    except OSError as err:
        _warn(err)
        return None


def _warn(err: BaseException) -> None:
    sys.stderr.write(f"warning: running the model in CasADi's VM, not native code: {err}\n")


@dataclass
class _Job:
    """One library to compile: its source, where the compiler writes, where it goes."""

    source: Path
    partial: Path
    library: Path
    process: subprocess.Popen | None = None
    error: str | None = None

    @property
    def done(self) -> bool:
        return self.library.exists() or self.error is not None


class NativeBuild:
    """The native versions of some functions, compiled by background processes.

    The C sources are generated at once; a library already in the cache is
    used as it is, the others are queued for the compilers (`_advance`: one
    per core, and one core left to the caller while it works).  `ready()`
    returns the native functions once every library is there, and None until
    then, so the caller runs the functions in CasADi's VM meanwhile and
    switches when they are ready: a first run is never slower than the VM by
    more than the sources' generation.  `wait()` blocks until they are.  A
    compiler that fails leaves the VM functions in use (warned once).
    Libraries above `VM_SOURCE_BYTES` of source are not compiled.
    """

    def __init__(self, functions: list[ca.Function], cc: str) -> None:
        self.functions = list(functions)
        self._native: list[ca.Function] | None = None
        self.failed = False
        folder = cache_folder()
        folder.mkdir(parents=True, exist_ok=True)
        self._folder = Path(tempfile.mkdtemp(prefix=".cpas-cg-", dir=folder))
        _LIVE.folders.append(self._folder)
        try:
            sources = [_generate(fn, self._folder / str(i)) for i, fn in enumerate(functions)]
        except BaseException:
            self._remove_folder()
            raise
        self.libraries = [folder / f"{fn.name()}-{_digest(src)}.so"
                          if src.stat().st_size <= VM_SOURCE_BYTES else None
                          for fn, src in zip(functions, sources, strict=True)]
        self._jobs = [_QUEUE.job(src, lib, cc) for src, lib in zip(sources, self.libraries,
                                                                  strict=True)
                      if lib is not None and not lib.exists()]
        COUNTS["builds"] += bool(self._jobs)
        if self._jobs and sys.stderr.isatty():
            sys.stderr.write(f"  compiling {len(self._jobs)} model functions to native code "
                             f"(once per model structure; cache {folder}) ...\n")
        _QUEUE.advance()

    @property
    def pending(self) -> int:
        """Libraries still to compile."""
        return sum(not job.done for job in self._jobs)

    def ready(self) -> list[ca.Function] | None:
        """The native functions, once every library is compiled; None before (and for good
        where a compiler failed)."""
        if self._native is not None or self.failed:
            return self._native
        _QUEUE.advance()
        if self.pending:
            return None
        errors = [job.error for job in self._jobs if job.error is not None]
        self._remove_folder()
        if errors:
            self.failed = True
            _warn(RuntimeError(errors[0]))
            return None
        self._native = [fn if lib is None else ca.external(fn.name(), str(lib))
                        for fn, lib in zip(self.functions, self.libraries, strict=True)]
        return self._native

    def wait(self) -> list[ca.Function]:
        """The native functions, waited for (the VM functions where a compiler failed).
        Interrupted (Ctrl-C, SIGTERM, any error), every compiler of this build is killed."""
        try:
            while (native := self.ready()) is None and not self.failed:
                time.sleep(0.05)
        except BaseException:
            self.cancel()
            raise
        return native if native is not None else list(self.functions)

    def cancel(self) -> None:
        """Kill this build's compilers and remove its folder."""
        _QUEUE.cancel(self._jobs)
        self._remove_folder()

    def _remove_folder(self) -> None:
        shutil.rmtree(self._folder, ignore_errors=True)
        if self._folder in _LIVE.folders:
            _LIVE.folders.remove(self._folder)


class _Queue:
    """The libraries waiting for a compiler and those compiling, for the whole process
    (a library two builds need is compiled once)."""

    def __init__(self) -> None:
        self.waiting: list[tuple[_Job, str]] = []
        self.running: list[_Job] = []
        self._by_library: dict[Path, _Job] = {}

    def job(self, source: Path, library: Path, cc: str) -> _Job:
        """The job making `library` from `source`, queued unless one is under way."""
        job = self._by_library.get(library)
        if job is None or job.error is not None:
            job = _Job(source, source.parent / library.name, library)
            self._by_library[library] = job
            self.waiting.append((job, cc))
        return job

    def advance(self) -> None:
        """Collect the compilers that ended and start waiting ones: one per core, but one
        core left to the process while it has work (`in_background`)."""
        for job in [j for j in self.running if j.process.poll() is not None]:
            self.running.remove(job)
            _LIVE.compilers.remove(job.process)
            if job.process.returncode == 0:
                os.replace(job.partial, job.library)  # atomic: a library is always complete
            else:
                err = (job.partial.parent / "stderr").read_bytes().decode(errors="replace")
                job.error = f"compiling {job.library.name} failed: {err[-500:]}"
        limit = max(_cores() - 1, 1) if in_background() else _cores()
        while self.waiting and len(self.running) < limit:
            job, cc = self.waiting.pop()  # the newest first: the model in use now
            if job.done:
                continue
            # A signal waits until the compiler is on the list of those to kill (one
            # raised inside Popen would leave it running, unlisted).  Each runs in a
            # process group of its own (the driver with its cc1 and as), killed whole,
            # since killing the driver alone leaves its cc1 running.
            with open(job.source.parent / "stderr", "wb") as err, interrupts.deferred():
                job.process = subprocess.Popen(
                    [cc, optimisation(job.source), *FLAGS, "-o", str(job.partial),
                     str(job.source), "-lm"], stdout=subprocess.DEVNULL, stderr=err,
                    start_new_session=True, preexec_fn=_lowest_priority if in_background()
                    else None)
                self.running.append(job)
                _LIVE.compilers.append(job.process)
                COUNTS["libraries"] += 1

    def cancel(self, jobs: list[_Job]) -> None:
        """Kill and forget `jobs`."""
        for job in jobs:
            self.waiting = [(j, cc) for j, cc in self.waiting if j is not job]
            if job in self.running:
                self.running.remove(job)
                _LIVE.compilers.remove(job.process)
                _kill_group(job.process)
            if not job.library.exists():
                job.error = "cancelled"


_QUEUE = _Queue()


def _lowest_priority() -> None:
    """In a compiler started in the background: the lowest scheduling priority, so the
    work it runs beside (the model in CasADi's VM) keeps the cores it uses."""
    os.nice(19)


@dataclass
class _Live:
    """The compilers running and the temporary folders they write in, for `abandon`."""

    compilers: list[subprocess.Popen] = field(default_factory=list)
    folders: list[Path] = field(default_factory=list)


_LIVE = _Live()


def abandon() -> None:
    """Kill every running compiler and remove the temporary folders: for a process that
    must end at once, without unwinding (a local worker of a campaign told to stop), and
    at the end of every process (a library not finished by then is not needed by it)."""
    for proc in _LIVE.compilers:
        _kill_group(proc)
    _LIVE.compilers.clear()
    _QUEUE.waiting.clear()
    _QUEUE.running.clear()
    for folder in _LIVE.folders:
        shutil.rmtree(folder, ignore_errors=True)
    _LIVE.folders.clear()


def _forget_the_parents() -> None:
    """In a forked child: the compilers and folders are the parent's, not its own."""
    global _QUEUE, _LIVE
    _QUEUE, _LIVE = _Queue(), _Live()


atexit.register(abandon)
os.register_at_fork(after_in_child=_forget_the_parents)


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
