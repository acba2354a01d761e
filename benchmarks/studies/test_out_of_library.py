"""Effects the library lacks, found by `discover` through the plug-ins it writes from the
residual's signature.

Two FBCP phases are flown with physics no library effect describes:

* a load-cell reading that loses 8e-6 of itself per newton of tension
  (`tests/plugins/tension_loss.py`; 15 % at the 19 kN peak);
* an east wind through a shear layer, S L tanh((h - 6,800 m) / L) with
  S = 0.03 /s and L = 300 m (`tests/plugins/wind_shear.py`; 12 m/s across
  the phase's 500 m of descent, not linear in altitude).

`discover` from the baseline fit must write the plug-in the signature asks
for (a tension-dependent load-cell gain; a wind profile in altitude), find it
significant as written, add it, and end with residuals consistent with the
noise: chi-square within 4 standard deviations, sqrt(2 dof), of its dof.  The
library effects that fit part of a signal on the way are reported as
partial, and the ones the model no longer needs are dropped: the chain ends
with no effect the truth lacks.  (The periodic
case, canopy breathing, is `benchmarks/studies/test_breathing_plugin.py`.)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from cpas_ocp.discrepancy.discovery import discover
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.registry import load_plugin
from cpas_ocp.reports.discrepancy_text import discovery_text

pytestmark = pytest.mark.slow

PLUGINS = Path(__file__).parents[2] / "tests" / "plugins"


def _discover(folder: Path, plugin: str, truth: dict[str, float], first: bool):
    """Simulate `fbcp` with the plug-in effect `plugin` (first in the effect list, or
    last), fit the baseline from the reduction, and discover from there."""
    path = PLUGINS / f"{plugin}.py"
    effect = next(iter(load_plugin(path).values())).build({}, str(path), "test")
    problem = load_problem("fbcp")
    base = baseline_effects()
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **truth}), folder,
                     1, effects=[effect, *base] if first else [*base, effect])
    (folder / "truth.json").unlink()
    fit = Estimator(load_test(folder), baseline_spec()).solve()
    return discover(fit, baseline_spec())


def _ends_at_the_noise(found, proposed: str) -> None:
    """Consistent with the noise, with no effect kept that the truth lacks: the baseline and
    the plug-in written for the hidden physics, nothing else."""
    last = found.steps[-1].fit
    assert found.stopped == "the residuals are consistent with the noise", discovery_text(found)
    assert found.state == "consistent"
    assert abs(last.chi_square - last.dof) < 4.0 * (2.0 * last.dof) ** 0.5
    kept = set(found.steps[-1].spec.effect_names) - set(baseline_spec().effect_names)
    assert kept == {proposed}, discovery_text(found)


@pytest.fixture(scope="module")
def tension_loss(tmp_path_factory):
    return _discover(tmp_path_factory.mktemp("tension-loss") / "test", "tension_loss",
                     {f"tension_loss[{c}]": 8e-6 for c in ("fbcp1", "fbcp2")}, first=False)


@pytest.fixture(scope="module")
def wind_shear(tmp_path_factory):
    return _discover(tmp_path_factory.mktemp("wind-shear") / "test", "wind_shear",
                     {"shear_rate": 0.03}, first=True)


def test_a_tension_dependent_loss_is_written_as_a_load_cell_gain(tension_loss) -> None:
    found = tension_loss
    trial = next(t for t in found.proposals if t.proposal.name == "tension_gain")
    assert trial.confirmed and "correlates with" in trial.proposal.reason
    assert "tension_gain" in found.steps[-1].spec.effect_names
    # The reading loses more the higher the load: the gain falls with the tension.
    for name in ("tension_gain[fbcp1]", "tension_gain[fbcp2]"):
        assert found.steps[-1].fit.parameters[name] < 0.0, name
    _ends_at_the_noise(found, "tension_gain")


def test_a_shear_layer_is_written_as_a_wind_profile(wind_shear) -> None:
    found = wind_shear
    trial = next(t for t in found.proposals if t.proposal.name == "wind_profile")
    assert trial.confirmed and "altitude" in trial.proposal.reason
    final = found.steps[-1]
    assert "wind_profile" in final.spec.effect_names
    # The east wind grows with altitude (S > 0): the profile's east shear is positive.
    assert final.fit.parameters["wind_shear_east"] > 0.0
    _ends_at_the_noise(found, "wind_profile")
    # A library effect added before the profile as a partial step, and no longer needed
    # after it, is dropped by a step of its own whose likelihood ratio is not significant.
    for step in found.steps:
        if step.dropped is not None:
            assert step.dropped not in step.spec.effect_names
            assert "keeping it is not significant" in step.admitted_by


def test_proposed_files_are_plug_ins_a_user_can_read(wind_shear, tmp_path) -> None:
    """Each proposal is a file that loads as a plug-in, documents the signature it answers,
    and names its constants at the top for the user to edit."""
    for trial in wind_shear.proposals:
        path = tmp_path / trial.proposal.file_name
        path.write_text(trial.proposal.source)
        assert list(load_plugin(path)) == [trial.proposal.name]
        doc = trial.proposal.source.split('"""')[1]
        assert "Proposed from the residual's signature" in doc
