"""Native code for the model's pieces (`chained_jacobians`), compiled once per machine.

CasADi evaluates SX functions in its virtual machine.  The same function
emitted as C and compiled by the system C compiler at -O1 (-O0 for very
large sources, and none above `VM_SOURCE_BYTES`) runs about four times
faster on an RK4 step's Jacobian (and -O2 costs twice the compile time for
10 % more).  The C source is hashed and the shared library kept under that
hash in the cache folder (``$CPAS_OCP_CACHE``, else ``~/.cache/cpas-ocp``),
so a piece is compiled once per machine: every test folder with the same
vehicle, parachutes, sensors and atmosphere reuses it.

A model met for the first time runs in the VM.  Its pieces compile only where
that can pay within the process (`NativeBuild`): once the process builds a
second estimator (a diagnosis, a discovery, a campaign's worker) or a run has
made `nlp_functions.SWITCH_AFTER` evaluations; the estimator switches to them
once they are all there.  A process that did neither (one short fit: a
`reconstruct` of `drogue` makes 25 evaluations) leaves its pieces to one
compiler started as it ends, at the lowest priority, which outlives it, so
the next run finds them: a first run is a VM run (`benchmarks/compile_cost.py`).
``CPAS_OCP_COMPILE=wait`` compiles first; ``CPAS_OCP_COMPILE=0``, or no C
compiler, keeps the VM.  Compiled functions carry no derivatives: each piece
comes with a separately compiled Jacobian.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import suppress
from dataclasses import dataclass
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
# and no minutes or gigabytes of compiling.  That output's states at t - tau are now
# chained through the step piece, and the largest piece of the library's models is the
# RK4 step's Jacobian of `drogue` with added mass, 1.3 MB.
LARGE_SOURCE_BYTES = 3_000_000
VM_SOURCE_BYTES = 4_000_000
# Builds that queued a library no build had queued before, and compilers started, in this
# process (benchmarks).
COUNTS = {"builds": 0, "libraries": 0}


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

    The C sources are generated at once (each in a folder of its own in the
    cache); a library already in the cache is used as it is, the others are
    queued for the compilers (`_Queue.advance`: one per core, and one core
    left to the caller while it works).  `ready()` returns the native
    functions once every library is there, and None until then, so the caller
    runs the functions in CasADi's VM meanwhile and switches when they are
    ready.  `wait()` blocks until they are.  A compiler that fails leaves the
    VM functions in use (warned once).  Libraries above `VM_SOURCE_BYTES` of
    source are not compiled.
    """

    def __init__(self, functions: list[ca.Function], cc: str) -> None:
        self.functions = list(functions)
        self._native: list[ca.Function] | None = None
        self.failed = False
        cache = cache_folder()
        cache.mkdir(parents=True, exist_ok=True)
        _sweep_stale(cache)
        self.libraries: list[Path | None] = []
        self._jobs: list[_Job] = []
        fresh = False  # whether this build queued a library no other build had
        for fn in functions:
            folder = Path(tempfile.mkdtemp(prefix=".cpas-cg-", dir=cache))
            _FOLDERS.append(folder)
            try:
                src = _generate(fn, folder)
            except BaseException:
                _remove(folder)
                raise
            lib = (cache / f"{fn.name()}-{_digest(src)}.so"
                   if src.stat().st_size <= VM_SOURCE_BYTES else None)
            self.libraries.append(lib)
            job = None if lib is None or lib.exists() else _QUEUE.job(src, lib, cc)
            if job is None or job.source != src:  # cached, not compiled, or under way
                _remove(folder)
            if job is not None:
                self._jobs.append(job)
                fresh = fresh or job.source == src
        COUNTS["builds"] += fresh
        _QUEUE.builds += 1
        if _QUEUE.builds > 1 or not in_background():  # a process of several fits
            _QUEUE.start()
        if self._jobs and sys.stderr.isatty():
            sys.stderr.write(f"  {len(self._jobs)} model functions to compile to native code "
                             f"(once per model structure; cache {cache})\n")
        _QUEUE.advance()

    @property
    def pending(self) -> int:
        """Libraries still to compile."""
        return sum(not job.done for job in self._jobs)

    def ready(self, start: bool = True) -> list[ca.Function] | None:
        """The native functions, once every library is compiled; None before (and for good
        where a compiler failed).  With `start`, the compilers start if they had not (a
        run that asks has shown it is long); without, only libraries already there count."""
        if self._native is not None or self.failed:
            return self._native
        if start:
            _QUEUE.start()
        _QUEUE.advance()
        if self.pending:
            return None
        errors = [job.error for job in self._jobs if job.error is not None]
        if errors:
            self.failed = True
            _warn(RuntimeError(errors[0]))
            return None
        self._native = [fn if lib is None else ca.external(fn.name(), str(lib))
                        for fn, lib in zip(self.functions, self.libraries, strict=True)]
        return self._native

    def wait(self) -> list[ca.Function]:
        """The native functions, waited for (the VM functions where a compiler failed).
        Interrupted (Ctrl-C, SIGTERM, any error), every compiler of this build is killed;
        a signal held back by the estimator's build (`interrupts.deferred`) ends the wait
        too, with the VM functions, so that the build ends and the signal is raised."""
        try:
            while (native := self.ready()) is None and not self.failed:
                if interrupts.pending():  # a signal waits for the build around this to end
                    _QUEUE.cancel(self._jobs)
                    return list(self.functions)
                time.sleep(0.05)
        except BaseException:
            _QUEUE.cancel(self._jobs)
            raise
        return native if native is not None else list(self.functions)


# A compiler's command: the library is compiled beside its source, moved into the cache in
# one rename (a library in the cache is always complete) and the source's folder removed,
# by the job itself, so that one still running when the process ends finishes on its own.
_JOB = ('cc=$1; shift; "$cc" "$@" && mv -f "$PARTIAL" "$LIBRARY" && rm -rf "$FOLDER"; '
        'status=$?; rm -f "$CLAIM"; exit $status')


def _claim_file(library: Path) -> Path:
    """Where a process that compiles `library` says so (`_claim`)."""
    return library.with_name(library.name + ".claim")


def _claim(library: Path) -> bool:
    """Claim the compiling of `library` for this process, across processes that share the
    cache: False where another live process holds the claim (its compiler will put the
    library in place, so this process waits for it instead of compiling it too).

    A claim is a file beside the library holding the compiling process's id, made in one
    step (O_EXCL); its compiler's shell removes it as it ends, and a claim whose process
    has ended or that is older than STALE_FOLDER_S is taken over.  Only the work is
    shared: a library goes into the cache in one rename whoever compiles it, so a claim
    lost or taken over costs time, never a wrong library.  Two suite workers, or two
    campaign workers, that meet the same model compiled each of its libraries twice.
    """
    claim = _claim_file(library)
    for _ in range(2):
        try:
            fd = os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            if _claim_live(claim):
                return False
            with suppress(OSError):
                claim.unlink()
            continue
        except OSError:  # a cache that cannot hold the claim: compile here
            return True
        with os.fdopen(fd, "w") as out:
            out.write(str(os.getpid()))
        return True
    return False


def _claim_live(claim: Path) -> bool:
    """Whether the process that made `claim` still runs and the claim is not stale."""
    try:
        owner = claim.read_text()
        age = time.time() - claim.stat().st_mtime
    except OSError:  # gone meanwhile: look again at the next advance
        return True
    if age > STALE_FOLDER_S:
        return False
    if not owner:  # just made, its process id not yet written
        return True
    try:
        os.kill(int(owner), 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except (OSError, ValueError):  # not a process id: not a claim of ours
        return False
    return True


def _release(library: Path) -> None:
    """Remove this process's claim on `library` (a compiler killed or failed to start)."""
    with suppress(OSError):
        _claim_file(library).unlink()


class _Queue:
    """The libraries waiting for a compiler and those compiling, for the whole process
    (a library two builds need is compiled once)."""

    def __init__(self) -> None:
        self.waiting: list[tuple[_Job, str]] = []
        self.running: list[_Job] = []
        self._by_library: dict[Path, _Job] = {}
        self.builds = 0  # NativeBuilds made in this process
        self.started = False  # whether compilers run during the process (module docstring)

    def start(self) -> None:
        """Let compilers run from now on."""
        self.started = True

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
        for job, process in [(j, j.process) for j in self.running]:
            if process is None or process.poll() is None:
                continue
            self.running.remove(job)
            if process.returncode != 0:
                err = (job.source.parent / "stderr").read_bytes().decode(errors="replace")
                job.error = f"compiling {job.library.name} failed: {err[-500:]}"
            _remove(job.source.parent)
        limit = max(_cores() - 1, 1) if in_background() else _cores()
        i = len(self.waiting)  # the newest first: the model in use now
        while self.started and i > 0 and len(self.running) < limit:
            i -= 1
            job, cc = self.waiting[i]
            if job.done:
                del self.waiting[i]
                _remove(job.source.parent)
                continue
            if not _claim(job.library):  # another process compiles it: wait for it
                continue
            del self.waiting[i]
            # A signal waits until the compiler is on the list of those to kill (one
            # raised inside Popen would leave it running, unlisted).  Each runs in a
            # process group of its own (the shell with the driver, its cc1 and as),
            # killed whole, since killing the driver alone leaves its cc1 running.
            env = {**os.environ, "PARTIAL": str(job.partial), "LIBRARY": str(job.library),
                   "FOLDER": str(job.source.parent), "CLAIM": str(_claim_file(job.library))}
            with open(job.source.parent / "stderr", "wb") as err, interrupts.deferred():
                try:
                    job.process = subprocess.Popen(
                        ["sh", "-c", _JOB, "sh", cc, optimisation(job.source), *FLAGS, "-o",
                         str(job.partial), str(job.source), "-lm"], env=env,
                        stdout=subprocess.DEVNULL, stderr=err, start_new_session=True,
                        preexec_fn=_lowest_priority if in_background() else None)
                except BaseException:
                    _release(job.library)
                    raise
                self.running.append(job)
                # The claim is the compiler's from now on: it outlives this process.
                with suppress(OSError):
                    _claim_file(job.library).write_text(str(job.process.pid))
                COUNTS["libraries"] += 1

    def cancel(self, jobs: list[_Job]) -> None:
        """Kill and forget `jobs`, and remove their folders."""
        for job in jobs:
            self.waiting = [(j, cc) for j, cc in self.waiting if j is not job]
            if job in self.running and job.process is not None:
                self.running.remove(job)
                _kill(job.process, job.library)
            if not job.library.exists():
                job.error = "cancelled"
            _remove(job.source.parent)


_QUEUE = _Queue()


def advance_compilers() -> None:
    """Collect the compilers that ended and, once compilers may run (`_Queue.start`),
    start those waiting (`_Queue.advance`)."""
    _QUEUE.advance()


# A compiler's folder this old belongs to a process killed outright (SIGKILL): no compile
# takes an hour (the longest measured, 400 s).
STALE_FOLDER_S = 3600.0


def _sweep_stale(cache: Path) -> None:
    """Remove the compilers' folders in `cache` older than STALE_FOLDER_S."""
    now = time.time()
    for folder in cache.glob(".cpas-cg-*"):
        with suppress(OSError):
            if now - folder.stat().st_mtime > STALE_FOLDER_S:
                shutil.rmtree(folder, ignore_errors=True)


def _remove(folder: Path) -> None:
    """Remove a compiler's folder and forget it."""
    shutil.rmtree(folder, ignore_errors=True)
    if folder in _FOLDERS:
        _FOLDERS.remove(folder)


def _lowest_priority() -> None:
    """In a compiler started in the background: the lowest scheduling priority, so the
    work it runs beside (the model in CasADi's VM) keeps the cores it uses."""
    os.nice(19)


# The compilers' temporary folders of this process (sources, partial libraries), for
# `abandon`; the compilers themselves are `_QUEUE.running`'s.
_FOLDERS: list[Path] = []


def abandon() -> None:
    """Kill every running compiler and remove the temporary folders: for a process that
    must end at once, without unwinding (a local worker of a campaign told to stop), and
    at the end of a process a signal stopped."""
    for job in _QUEUE.running:
        if job.process is not None:
            _kill(job.process, job.library)
    _QUEUE.waiting.clear()
    _QUEUE.running.clear()
    for folder in _FOLDERS:
        shutil.rmtree(folder, ignore_errors=True)
    _FOLDERS.clear()


def _at_exit() -> None:
    """At the end of the process: stopped by a signal, drop every compile (`abandon`);
    else leave the running ones to finish and hand those not started to one compiler
    process that builds them one after another at the lowest priority and outlives this
    one (`_compile_after_exit`), so the next run finds their libraries."""
    if interrupts.received():
        abandon()
        return
    waiting, _QUEUE.waiting = _QUEUE.waiting, []
    waiting = [(job, cc) for job, cc in waiting if not job.done]
    if waiting:
        _compile_after_exit(waiting)
    for job, _ in waiting:  # the folders are the compiler's now
        if job.source.parent in _FOLDERS:
            _FOLDERS.remove(job.source.parent)


def _compile_after_exit(jobs: list[tuple[_Job, str]]) -> None:
    """Start one detached shell (a session of its own, at the lowest priority) that
    compiles `jobs` one after another, each as a queued job would (`_JOB`), and removes
    the folder of one that fails."""
    lines = []
    for job, cc in jobs:
        folder = job.source.parent
        command = ["sh", "-c", _JOB, "sh", cc, optimisation(job.source), *FLAGS, "-o",
                   str(job.partial), str(job.source), "-lm"]
        env = " ".join(f"{k}={shlex.quote(str(v))}" for k, v in
                       (("PARTIAL", job.partial), ("LIBRARY", job.library), ("FOLDER", folder)))
        lines.append(f"{env} {shlex.join(command)} 2>/dev/null || rm -rf "
                     f"{shlex.quote(str(folder))}")
    with suppress(OSError):
        subprocess.Popen(["sh", "-c", "\n".join(lines)], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True, preexec_fn=_lowest_priority)


def _forget_the_parents() -> None:
    """In a forked child: the compilers and folders are the parent's, not its own."""
    global _QUEUE
    _QUEUE = _Queue()
    _FOLDERS.clear()


atexit.register(_at_exit)
os.register_at_fork(after_in_child=_forget_the_parents)


def _kill(proc: subprocess.Popen, library: Path) -> None:
    """Kill the process group `proc` leads (a compiler driver and the passes it started),
    wait for the driver, and release the claim on the `library` it was making (its shell,
    killed, cannot); the group's other members, orphaned, are reaped by init."""
    with suppress(ProcessLookupError):  # the whole group has already ended
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    _release(library)


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() or 1


def _generate(fn: ca.Function, folder: Path) -> Path:
    """The C source of `fn`, written into the existing `folder`."""
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
