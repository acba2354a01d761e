"""A discovery's finished steps as data on disk, and the chain read back from them.

`discover` writes its folder again at every point where the chain is whole
(a step appended and its stand-ins dropped, or a step diagnosed), in one
atomic swap of folders (`output_folder.atomic_folder`): a run stopped by
any signal, SIGKILL included, or by the machine, leaves the last whole chain
readable.  Beside the report's files the folder then holds what it takes to
go on (`RESUME_FILE`, and per step `step_K.fit.npz`: the fit's decision
vector and multipliers), and `read_checkpoint` rebuilds the chain: each
step's model from its model file, its estimator from the settings it was
built with, and its fit evaluated at the stored decision vector (no solve,
so the chi-square is the one written).  Diagnoses are not stored: the last
step's is made again, from the same fit, so a resumed chain goes on as the
uninterrupted one would; earlier steps keep the verdict and worst window
they had.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cpas_ocp.discrepancy.candidate_plugins import Proposal
from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, ProposalTrial
from cpas_ocp.discrepancy.refinement import RefinementTrial
from cpas_ocp.discrepancy.score_test import ScoreTest
from cpas_ocp.discrepancy.sparse_terms import TermSelection
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.fit import Settings, SolverStats
from cpas_ocp.inference.diagnostics import WindowStatistic
from cpas_ocp.inference.model_comparison import LikelihoodRatio
from cpas_ocp.io.model_spec import load_model_file
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.effects.registry import EffectType, load_plugin
from cpas_ocp.physics.flight_test import FlightTest

RESUME_FILE = "resume.json"
FORMAT = 1


def fit_file(k: int) -> str:
    """The file holding step k's decision vector and multipliers."""
    return f"step_{k}.fit.npz"


def write_checkpoint(discovery: Discovery, folder: Path, context: Mapping[str, Any]) -> None:
    """The data to go on from `discovery` into `folder` (being written: see the module
    docstring); `context` is what the caller needs to rebuild its run (the test folder,
    the options), kept as given."""
    steps = []
    for k, s in enumerate(discovery.steps):
        np.savez(folder / fit_file(k), z=s.fit.z, multipliers=np.asarray(s.fit.multipliers))
        worst = s.worst_window
        steps.append({
            "added": s.added, "dropped": s.dropped, "refined": s.refined,
            "refinement": s.refinement, "admitted_by": s.admitted_by,
            "explained": s.explained, "stand_in": s.stand_in, "start": s.start,
            "searched": s.searched, "found_s": s.found_s, "diagnosed_s": s.diagnosed_s,
            "windows_explained": [[dataclasses.asdict(a), dataclasses.asdict(b), share]
                                  for a, b, share in s.windows_explained],
            "verdict": s.verdict,
            "worst_window": None if worst is None else list(worst),
            "settings": _settings_json(s.fit.settings),
            "solver": dataclasses.asdict(s.fit.solver),
            "guess": s.fit.guess})
    data = {"format": FORMAT, "context": dict(context), "alpha": discovery.alpha,
            "notes": discovery.notes, "steps": steps,
            "proposals": [{"step": t.step, "tried": t.tried, "confirmed": t.confirmed,
                           "name": t.proposal.name, "reason": t.proposal.reason,
                           "test": t.test.as_dict()} for t in discovery.proposals],
            "refinements": [t.as_dict() for t in discovery.refinements],
            "regressions": [t.as_dict() for t in discovery.regressions]}
    (folder / RESUME_FILE).write_text(json_text(data))


def checkpoint_context(folder: Path) -> dict[str, Any]:
    """The caller's context stored in the checkpoint in `folder` (InputError where there is
    none to go on from)."""
    return _read(folder)["context"]


def read_checkpoint(folder: Path, test: FlightTest,
                    plugins: Mapping[str, EffectType] | None = None) -> Discovery:
    """The chain stored in `folder` (module docstring), on `test`, with the plug-in effects
    `plugins` (those of --plugin) and the proposed ones the folder holds."""
    data = _read(folder)
    out = Discovery(alpha=data["alpha"], notes=list(data["notes"]))
    for file in sorted((folder / "proposed").glob("*.py")) if (folder / "proposed").is_dir() \
            else []:
        out.plugins.update(load_plugin(file))
    registry = {**(plugins or {}), **out.plugins}
    for item in data["proposals"]:
        source = (folder / "proposed" / f"{item['name']}.py").read_text()
        out.proposals.append(ProposalTrial(item["step"], Proposal(item["name"], item["reason"],
                                                                   source),
                                           _score_test(item["test"]), item["tried"],
                                           item["confirmed"]))
    out.refinements = [RefinementTrial.from_dict(t) for t in data.get("refinements", [])]
    out.regressions = [TermSelection.from_dict(t) for t in data.get("regressions", [])]
    for k, item in enumerate(data["steps"]):
        spec = load_model_file(folder / f"step_{k}.json", registry, allow_external=True)
        stored = np.load(folder / fit_file(k))
        # The step's own starting values: no reduction to repeat (they are its result).
        settings = _settings(item["settings"])
        est = Estimator(test, spec, dataclasses.replace(
            settings, guess={**item["guess"], **settings.guess}))
        fit = est.fit_at(stored["z"], SolverStats(**item["solver"]))
        fit.multipliers = stored["multipliers"]
        fit.guess = dict(item["guess"])
        out.steps.append(DiscoveryStep(
            item["added"], spec, fit, item["admitted_by"], explained=_number(item["explained"]),
            windows_explained=[(_window(a), _window(b), _number(share))
                               for a, b, share in item["windows_explained"]],
            stand_in=list(item["stand_in"]), dropped=item["dropped"],
            refined=item.get("refined"), refinement=item.get("refinement", ""), estimator=est,
            start=item["start"], searched=item["searched"], found_s=item["found_s"],
            diagnosed_s=item["diagnosed_s"], recorded_verdict=item["verdict"],
            recorded_worst=None if item["worst_window"] is None
            else (item["worst_window"][0], item["worst_window"][1])))
    return out


def _number(value: float | None) -> float:
    """A number strict JSON held (null for a non-finite one: NaN again)."""
    return float("nan") if value is None else float(value)


def _window(data: Mapping[str, Any]) -> WindowStatistic:
    return WindowStatistic(**{k: _number(v) if v is None else v for k, v in data.items()})


def _read(folder: Path) -> dict[str, Any]:
    path = folder / RESUME_FILE
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(str(path), "(file)", "a discovery folder written by `cpas-ocp "
                         "discover` (it holds resume.json)") from None
    except (OSError, ValueError) as exc:
        raise InputError(str(path), "(file)", f"readable JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError(str(path), "format", f"{FORMAT} (written by this version)")
    return data


def _settings_json(settings: Settings) -> dict[str, Any]:
    return {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}


def _settings(data: Mapping[str, Any]) -> Settings:
    """Settings from `_settings_json`'s JSON (tuples come back as lists)."""
    values = dict(data)
    for key in ("nodes", "interval_steps"):
        if values.get(key) is not None:
            values[key] = tuple(values[key])
    values["limits"] = {n: tuple(v) for n, v in values.get("limits", {}).items()}
    return Settings(**values)


def _score_test(data: Mapping[str, Any]) -> ScoreTest:
    """A score test from `ScoreTest.as_dict` (its refitted model and fit are not kept)."""
    values = {k: v for k, v in data.items() if k in {f.name for f in dataclasses.fields(ScoreTest)}}
    for name in ("statistic", "p_value"):
        if values.get(name) is None:
            values[name] = float("nan")
    for name in ("parameters", "one_sided", "undetermined", "beyond"):
        values[name] = tuple(values.get(name) or ())
    for name in ("estimate", "std"):  # an estimate beyond the bounds is stored as null
        values[name] = {n: float("nan") if v is None else v
                        for n, v in (values.get(name) or {}).items()}
    values["refit"] = LikelihoodRatio.from_dict(values.get("refit"))
    return ScoreTest(**values)
