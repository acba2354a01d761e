"""A discovery kept on disk as it goes, so that a stopped run keeps its finished steps and
goes on from them."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from cpas_ocp import interrupts
from cpas_ocp.discrepancy.discovery import (
    Discovery,
    DiscoveryStep,
    InterruptedDiscovery,
    discover,
)
from cpas_ocp.discrepancy.discovery_checkpoint import (
    checkpoint_context,
    read_checkpoint,
    write_checkpoint,
)
from cpas_ocp.errors import InputError, PluginError
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.io.output_folder import check_output
from cpas_ocp.physics.effects.registry import EffectType, load_plugins
from cpas_ocp.reports.discrepancy_report import write_discovery
from cpas_ocp.reports.display_units import DisplayUnits, display_units


def discovery_context(test_dir: str | Path, plugin_files: Sequence[str | Path], max_steps: int,
                      alpha: float, confirm: int, units: str | None) -> dict:
    """What a kept discovery stores to be resumed: the test folder, the plug-in files and
    the options, paths absolute."""
    return {"test_dir": str(Path(test_dir).resolve()),
            "plugin": [str(Path(f).resolve()) for f in plugin_files],
            "max_steps": max_steps, "alpha": alpha, "confirm": confirm, "units": units}


def discover_kept(out: str | Path, fit: Fit, spec: ModelSpec, plugins: Mapping[str, EffectType],
                  context: Mapping[str, Any], units: DisplayUnits | None = None, *,
                  estimator: Estimator | None = None, resume: Discovery | None = None,
                  progress: bool = False,
                  on_step: Callable[[DiscoveryStep], None] | None = None) -> Discovery:
    """`discover` from `fit` (of `spec`) with the folder `out` written whole, with signals
    held off, at every point the chain is whole: the report so far and what resuming
    needs (`discovery_checkpoint`; `context` from `discovery_context`, its "first_fit"
    a note the report keeps).  The options are the context's.  On a signal the finished
    steps are written, marked stopped with how to go on, and `InterruptedDiscovery` is
    raised again; a user's mistake (a plug-in that fails) leaves no folder it created."""
    out = Path(out)
    whole = [len(resume.steps) if resume is not None else 0]  # steps last written whole
    note = context.get("first_fit")

    def kept(chain: Discovery, figures: bool = False) -> Path:
        if note and note not in chain.notes:
            chain.notes.append(note)
        with interrupts.deferred():
            return write_discovery(chain, out, {**plugins, **chain.plugins}, units,
                                   figures=figures,
                                   extra=lambda tmp: write_checkpoint(chain, tmp, context))

    def checkpoint(chain: Discovery) -> None:
        kept(chain)
        whole[0] = len(chain.steps)

    new_folder = not out.exists() or not any(out.iterdir())
    try:
        found = discover(fit, spec, plugins, context["max_steps"], context["alpha"],
                         context["confirm"], progress=progress, on_step=on_step,
                         estimator=estimator, on_whole=checkpoint, resume=resume)
    except (InputError, PluginError):
        if new_folder:
            shutil.rmtree(out, ignore_errors=True)
        raise
    except InterruptedDiscovery as exc:
        # The chain as it last was whole (a step under way may have been appended since).
        exc.partial.steps = exc.partial.steps[:max(whole[0], 1)]
        exc.partial.stopped += f"; `cpas-ocp discover --resume {out}` goes on from here"
        kept(exc.partial)
        raise
    kept(found, figures=True)
    return found


def resume_discovery(folder: str | Path, progress: bool = False,
                     on_step: Callable[[DiscoveryStep], None] | None = None,
                     on_read: Callable[[Discovery], None] | None = None) -> Discovery:
    """Go on with the discovery kept in `folder` (`discover_kept`) from its last finished
    step, with its test folder, plug-in files and options; `on_read` is called with the
    chain read back, before the discovery goes on."""
    folder = Path(folder)
    context = checkpoint_context(folder)
    check_output(folder)
    test = load_test(context["test_dir"])
    plugins = load_plugins(context["plugin"])
    chain = read_checkpoint(folder, test, plugins)
    if on_read is not None:
        on_read(chain)
    return discover_kept(folder, chain.steps[0].fit, chain.steps[0].spec, plugins, context,
                         display_units(test, context["units"]), resume=chain,
                         progress=progress, on_step=on_step)
