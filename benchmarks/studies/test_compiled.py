"""Compiled per-instance values and Jacobians give exactly what CasADi's virtual machine
gives, whether waited for or switched to once compiled in the background."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.estimation import compiled
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.io.flight_test import load_test

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler here")]


def test_compiled_and_interpreted_estimators_agree(drogue_folder, tmp_path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CPAS_OCP_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CPAS_OCP_COMPILE", "wait")
    test = load_test(drogue_folder(1))
    vm = Estimator(test, settings=Settings(compile=False))
    native = Estimator(test, settings=Settings(compile=True))
    libraries = sorted(p.name.split("-")[0] for p in (tmp_path / "cache").glob("*.so"))
    # Per piece of the model (the RK4 step, each sensor group's outputs): its values and
    # its values with Jacobians.
    assert "rk4_step" in libraries and {f"{name}_d" for name in libraries
                                        if not name.endswith("_d")} == {
        n for n in libraries if n.endswith("_d")}

    z = vm.initial_point()
    z = z * (1.0 + 1e-3 * np.random.default_rng(7).standard_normal(z.size))  # off the guess
    for name in ("residual_jacobian", "constraints", "residual_value", "constraint_value"):
        a = getattr(vm.transcription.functions, name)(z)
        b = getattr(native.transcription.functions, name)(z)
        a, b = (out if isinstance(out, tuple) else (out,) for out in (a, b))
        for x, y in zip(a, b, strict=True):
            assert x.sparsity() == y.sparsity()
            assert float(ca.mmax(ca.fabs(x - y))) <= 1e-12 * max(float(ca.mmax(ca.fabs(x))), 1.0)
    # The Jacobian itself, against central differences of the residuals.
    v = np.random.default_rng(8).standard_normal(z.size)
    eps = 1e-6
    residual_jacobian = native.transcription.functions.residual_jacobian
    r_plus = np.asarray(residual_jacobian(z + eps * v)[0]).ravel()
    r_minus = np.asarray(residual_jacobian(z - eps * v)[0]).ravel()
    jv = np.asarray(ca.mtimes(residual_jacobian(z)[1], ca.DM(v))).ravel()
    np.testing.assert_allclose((r_plus - r_minus) / (2 * eps), jv, rtol=1e-4,
                               atol=1e-6 * np.max(np.abs(jv)))
    # The objective gradient handed to Ipopt is dense J'r.
    grad = native.ipopt.get_function("nlp_grad_f")(z, [])[1]
    r, J = residual_jacobian(z)
    assert grad.is_dense()
    np.testing.assert_allclose(np.asarray(grad).ravel(), np.asarray(ca.mtimes(J.T, r)).ravel(),
                               rtol=1e-12, atol=1e-9)

    # A second build finds every library in the cache and compiles nothing.
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").glob("*.so")}
    Estimator(test, settings=Settings(compile=True))
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").glob("*.so")} == stamps


def test_a_model_runs_in_the_vm_until_its_native_code_is_ready(problem_folder, tmp_path,
                                                                monkeypatch) -> None:
    """With an empty cache, the estimator evaluates in the VM while its pieces compile in
    the background, and a run that goes on (SWITCH_AFTER evaluations) switches to them: the
    same values and Jacobians either way (on `fbcp`, whose pieces compile soonest)."""
    monkeypatch.setenv("CPAS_OCP_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CPAS_OCP_COMPILE", "1")
    test = load_test(problem_folder("fbcp", 1))
    vm = Estimator(test, settings=Settings(compile=False))
    est = Estimator(test, settings=Settings(compile=True))
    z = vm.initial_point()
    points, reference = est.transcription.points, vm.transcription.points
    np.testing.assert_array_equal(points.residual_value(z), reference.residual_value(z))
    assert est.transcription.compiling is not None and points.switched_at is None  # still compiling
    est.transcription.compiling[0].wait()
    z2 = z * (1.0 + 1e-3 * np.random.default_rng(7).standard_normal(z.size))
    for name in ("residual_jacobian", "constraints"):
        if name == "constraints":  # a short run stays in the VM; a longer one switches
            assert points.switched_at is None
            monkeypatch.setattr("cpas_ocp.estimation.nlp_functions.SWITCH_AFTER", 2)
        a, b = getattr(points, name)(z2), getattr(reference, name)(z2)
        for x, y in zip(a, b, strict=True):
            x, y = (v.toarray() if hasattr(v, "toarray") else v for v in (x, y))
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12 * np.max(np.abs(y)))
    assert points.switched_at == 2  # after the two evaluations made in the VM


def test_a_single_fit_compiles_after_it_ends_for_the_next_run(problem_folder,
                                                              tmp_path) -> None:
    """One short fit in a process runs in the VM and hands its pieces to a compiler that
    outlives it: the libraries appear in the cache after the command has ended, and the
    next run compiles nothing."""
    import os
    import subprocess
    import sys
    import time
    cache = tmp_path / "cache"
    env = {**os.environ, "CPAS_OCP_CACHE": str(cache), "CPAS_OCP_COMPILE": "1"}

    def reconstruct(out: str) -> None:
        done = subprocess.run([sys.executable, "-m", "cpas_ocp.cli", "reconstruct",
                               str(problem_folder("fbcp", 3)), "--out", str(tmp_path / out)],
                              env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr[-2000:]

    reconstruct("first")
    began = time.monotonic()
    while list(cache.glob(".cpas-cg-*")) and time.monotonic() - began < 600:
        time.sleep(0.2)
    libraries = {p: p.stat().st_mtime_ns for p in cache.glob("*.so")}
    assert not list(cache.glob(".cpas-cg-*")) and "rk4_step" in {
        p.name.split("-")[0] for p in libraries}
    reconstruct("second")
    assert {p: p.stat().st_mtime_ns for p in cache.glob("*.so")} == libraries
    assert not list(cache.glob(".cpas-cg-*"))
