"""Where a model fails and what it lacks: a test's diagnosis, its discovery chain, and two
models of it compared, each from the test folder (the command line's `diagnose`,
`discover`, `compare`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from cpas_ocp.api.reconstruction import (
    FitOptions,
    as_test,
    build,
    fit_estimator,
    model_of,
    reconstruct,
    units_of,
)
from cpas_ocp.discrepancy.diagnosis import ALPHA, CONFIRM_TOP, Diagnosis
from cpas_ocp.discrepancy.discovery import MAX_STEPS, Discovery, DiscoveryStep
from cpas_ocp.errors import InputError
from cpas_ocp.inference.model_comparison import Comparison
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.registry import load_plugins
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.progress import SILENT, Narration
from cpas_ocp.reports.display_units import DisplayUnits


def diagnose(test: FlightTest | str | Path, out: str | Path | None = None,
             model: ModelSpec | str | Path | None = None, plugins: Sequence[str | Path] = (),
             confirm: int = CONFIRM_TOP, alpha: float = ALPHA,
             options: FitOptions | None = None, units: DisplayUnits | str | None = None,
             allow_external_plugins: bool = False, tell: Narration = SILENT) -> Diagnosis:
    """Fit `test`, then test every library effect and every effect of the plug-in files
    `plugins` the model leaves out (`Reconstruction.diagnose`; `cpas-ocp diagnose`); the
    folder written to `out` where given."""
    test = as_test(test)
    rec = reconstruct(test, model, load_plugins(plugins), options,
                      allow_external_plugins=allow_external_plugins, tell=tell)
    tell.say("testing the effects the model does not use ...")
    return rec.diagnose(out, confirm, alpha, tell.progress, units_of(test, units))


def discover(test_dir: str | Path, out: str | Path, model: ModelSpec | str | Path | None = None,
             plugins: Sequence[str | Path] = (), max_steps: int = MAX_STEPS,
             alpha: float = ALPHA, confirm: int = CONFIRM_TOP,
             options: FitOptions | None = None, units: str | None = None,
             allow_external_plugins: bool = False, tell: Narration = SILENT,
             on_step: Callable[[DiscoveryStep], None] | None = None) -> Discovery:
    """Fit the test in `test_dir`, then diagnose, add the confirmed effect, refit, and
    again (`Reconstruction.discover`; `cpas-ocp discover`), the folder `out` written whole
    wherever the chain is whole so that `resume_discovery(out)` goes on from a stopped
    run; `units`: "si", "us" or None for the manifest's, kept for a resumed run."""
    test = load_test(test_dir)
    rec = reconstruct(test, model, load_plugins(plugins), options,
                      allow_external_plugins=allow_external_plugins, tell=tell)
    tell.say("diagnosing, step by step ...")
    return rec.discover(out, max_steps, alpha, confirm, tell.progress, on_step,
                        units_of(test, units), plugins)


def compare(test: FlightTest | str | Path, models: Sequence[ModelSpec | str | Path],
            out: str | Path | None = None, plugins: Sequence[str | Path] = (),
            options: FitOptions | None = None, units: DisplayUnits | str | None = None,
            allow_external_plugins: bool = False, tell: Narration = SILENT) -> Comparison:
    """Two models of `test` fitted and tested against each other (`Reconstruction.compare`;
    `cpas-ocp compare`): each a spec, a model file (whose effects may be those of the
    plug-in files `plugins`) or "manifest" for the test's own; labelled by their files'
    names."""
    if len(models) != 2:
        raise InputError("(command line)", "--model",
                         f"exactly two models (--model A --model B); got {len(models)}")
    test = as_test(test)
    effects = load_plugins(plugins)
    specs = [model_of(test, None if m == "manifest" else m, effects, allow_external_plugins)
             for m in models]
    labels = tuple(Path(m.source).stem if isinstance(m, ModelSpec) else
                   "manifest" if m == "manifest" else Path(m).stem for m in models)
    if labels[0] == labels[1]:
        labels = (f"A: {labels[0]}", f"B: {labels[1]}")
    est = build(test, specs[0], None if options is None else options.settings, tell)
    tell.say(f"solving {labels[0]}: {est.size_text()} ...")
    rec = fit_estimator(est, options, effects, tell)
    tell.say(f"solving {labels[1]} from it ...")
    return rec.compare(specs[1], out, (labels[0], labels[1]), tell.progress,
                       units_of(test, units))
