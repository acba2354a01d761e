"""Shared fixtures: simulated Drogue test folders and their reconstructions (built once)."""

from __future__ import annotations

import importlib
import json
import os
import shutil
import signal
import sys
import types
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest
from scipy.stats import chi2
from threadpoolctl import threadpool_limits

from cpas_ocp import interrupts
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.parameters import split_name

START_GUESS_OFFSET_S = 0.3
# The thread counts OpenBLAS and OpenMP read when they load.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
TESTS = Path(__file__).parent


def patch_everywhere(monkeypatch: pytest.MonkeyPatch, name: str, value: object,
                     homes: Sequence[str]) -> None:
    """`name` replaced by `value` in each module of `homes`, all of them imported before any
    is patched.  A module first imported while another is patched binds the stand-in
    through its `from ... import name`, and monkeypatch then records the stand-in as the
    value to restore: it would stay for every later test in the process."""
    modules = [importlib.import_module(home) for home in homes]
    for module in modules:
        monkeypatch.setattr(module, name, value)


# The modules that bind `discovery.discover` by name: the command's path to it
# (`kept_discovery`) and the interface's in-memory one (`Reconstruction.discover`).
DISCOVER_HOMES = ("cpas_ocp.discrepancy.discovery", "cpas_ocp.api.kept_discovery",
                  "cpas_ocp.api.reconstruction")


def stand_ins_left() -> list[str]:
    """Functions and classes defined in the tests that sit in a module of the package (a
    patch that was never undone, or was undone to a stand-in)."""
    return sorted(f"{module_name}.{name}"
                  for module_name, module in list(sys.modules.items())
                  if module_name.split(".")[0] == "cpas_ocp"
                  for name, value in list(vars(module).items()) if _from_tests(value))


def _from_tests(value: object) -> bool:
    """Whether `value` is a function or a class defined in the tests."""
    if isinstance(value, types.FunctionType):
        return Path(value.__code__.co_filename).is_relative_to(TESTS)
    return isinstance(value, type) and value.__module__.split(".")[0] == "tests"


@pytest.fixture(autouse=True, scope="module")
def no_stand_in_left_behind() -> Iterator[None]:
    """A test module must leave the package and the process's signal handlers as it found
    them: a stand-in or a handler left behind silently changes what every later test in
    the same process runs."""
    handlers = {sig: signal.getsignal(sig) for sig in interrupts.SIGNALS}
    yield
    leaked = stand_ins_left()
    assert not leaked, f"stand-ins left in the package after this module: {leaked}"
    changed = [sig.name for sig, handler in handlers.items() if signal.getsignal(sig) != handler]
    assert not changed, f"signal handlers left changed after this module: {changed}"



def pytest_configure(config: pytest.Config) -> None:
    """With whole files handed to the workers (`--dist loadfile`), xdist would start the
    files with the most tests first, which puts the long files of a few slow tests last;
    the order `pytest_collection_modifyitems` gives is kept instead.

    Each of the workers holds BLAS (NumPy's and CasADi's OpenBLAS, and the processes its
    tests start) to its share of the cores, unless the thread counts are set in the
    environment.  Two workers on two cores, each with a pool of two BLAS threads that
    wait for work by spinning, took 6-10 % longer on the linear-algebra-heavy files and
    a sixth more CPU time (`benchmarks/suite_blas_threads.py`)."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers > 1 and not any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        threads = max(1, (os.cpu_count() or 1) // workers)
        for variable in BLAS_THREAD_VARIABLES:
            os.environ[variable] = str(threads)  # libraries loaded later, child processes
        threadpool_limits(threads)  # the libraries already loaded


@pytest.hookimpl(trylast=True)  # after `-m` has deselected: the tests that will run
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files with the most slow tests first, then those with the most tests, each
    file's tests in their own order: with two workers each taking whole files, the long
    files start early and the quick ones fill in beside them at the end."""
    slow: dict[Path, int] = {}
    count: dict[Path, int] = {}
    for item in items:
        count[item.path] = count.get(item.path, 0) + 1
        slow[item.path] = slow.get(item.path, 0) + (item.get_closest_marker("slow") is not None)
    items.sort(key=lambda item: (-slow[item.path], -count[item.path]))

@pytest.fixture(scope="session")
def problem_folder(tmp_path_factory: pytest.TempPathFactory):
    """A factory: the simulated test folder of a built-in problem and seed (simulated once)."""
    cache: dict[tuple[str, int], Path] = {}

    def make(problem: str, seed: int) -> Path:
        if (problem, seed) not in cache:
            folder = tmp_path_factory.mktemp(f"{problem}{seed}") / "test"
            simulate_problem(load_problem(problem), folder, seed)
            cache[problem, seed] = folder
        return cache[problem, seed]

    return make


@pytest.fixture(scope="session")
def drogue_folder(problem_folder):
    """A factory: the simulated `drogue` test folder for a seed."""
    return lambda seed: problem_folder("drogue", seed)


def offset_events(folder: Path, dest: Path, offset: float) -> Path:
    """Copy a test folder with every inflation-start event moved `offset` s off the truth.

    Signs alternate so that some guesses are early and some late.  Only the
    observed events change; the estimator takes its start-time guesses from them.
    """
    shutil.copytree(folder, dest)
    manifest = json.loads((dest / "manifest.json").read_text())
    truth = json.loads((dest / "truth.json").read_text())["parameters"]
    (dest / "truth.json").unlink()  # the estimator's folder carries no truth
    k = 0
    for event in manifest["events"]:
        if event["name"] in ("line_stretch", "bag_strip", "disreef"):
            stage = event.get("stage", "stage1")
            t_true = truth[f"t_start[{event['parachute']},{stage}]"]
            event["time"]["value"] = t_true + offset * (-1) ** k
            k += 1
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return dest


def event_errors(fit: Fit, truth: dict[str, float]) -> float:
    """Smallest distance (s) between an observed inflation-start event and the true start."""
    errors = [abs(e.time - truth[f"t_start[{e.parachute},{e.stage or 'stage1'}]"])
              for e in fit.test.events if e.name in ("line_stretch", "bag_strip", "disreef")]
    return min(errors)


@pytest.fixture(scope="session")
def problem_fit(problem_folder, tmp_path_factory: pytest.TempPathFactory):
    """A factory: (fit, covariance, truth) of a problem's seed with start guesses 0.3 s off."""
    cache: dict[tuple[str, int], tuple[Fit, Covariance, dict[str, float]]] = {}

    def make(problem: str, seed: int) -> tuple[Fit, Covariance, dict[str, float]]:
        if (problem, seed) not in cache:
            folder = problem_folder(problem, seed)
            truth = json.loads((folder / "truth.json").read_text())["parameters"]
            shifted = offset_events(
                folder, tmp_path_factory.mktemp(f"shifted-{problem}{seed}") / "test",
                START_GUESS_OFFSET_S)
            est = Estimator(load_test(shifted))
            fit = est.solve()
            cache[problem, seed] = (fit, est.covariance(fit), truth)
        return cache[problem, seed]

    return make


@pytest.fixture(scope="session")
def drogue_fit(problem_fit):
    """A factory: (fit, covariance, truth) of the `drogue` seed with start guesses 0.3 s off."""
    return lambda seed: problem_fit("drogue", seed)


def assert_sigmas_resolve(fit: Fit, cov: Covariance, relative: dict[str, float],
                          start_s: float) -> None:
    """The reported sigmas are small enough for a truth check to mean something:
    below `relative[base]` of the value for those bases, below `start_s` for start times."""
    std = cov.std
    for name in fit.free:
        base, _ = split_name(name)
        if base in relative:
            assert std[name] / fit.parameters[name] < relative[base], name
        if base == "t_start":
            assert std[name] < start_s, name


def assert_truth_within_noise(fit: Fit, cov: Covariance, truth: dict[str, float]) -> int:
    """Every estimate within 4 reported sigma of the truth, and jointly the squared
    Mahalanobis distance below the chi-square 0.999 quantile; returns its degrees of freedom."""
    std = cov.std
    z = {n: (fit.parameters[n] - truth[n]) / std[n] for n in fit.free}
    worst = max(z, key=lambda n: abs(z[n]))
    assert abs(z[worst]) < 4.0, f"{worst}: {z[worst]:.2f} sigma"
    m2, dof = cov.mahalanobis({n: fit.parameters[n] - truth[n] for n in fit.free})
    assert m2 < chi2.ppf(0.999, dof), f"Mahalanobis^2 {m2:.1f} on {dof} dof"
    return dof
