"""A chain's refinements and sparse regressions as its checkpoint keeps them: written as
strict JSON and read back to the same records, and printed with what they found."""

from __future__ import annotations

import json

from cpas_ocp.discrepancy.refinement import RefinementTrial
from cpas_ocp.discrepancy.sparse_terms import TermSelection
from cpas_ocp.inference.model_comparison import LikelihoodRatio
from cpas_ocp.io.strict_json import json_text


def _again(data: dict) -> dict:
    return json.loads(json_text(data))


def test_a_refinement_trial_reads_back_as_written() -> None:
    kept = RefinementTrial(1, "added_mass", "its growth exponent freed", 1,
                           LikelihoodRatio(595.21, 1), {"added_mass_exponent": 5.718}, kept=True)
    failed = RefinementTrial(2, "drag_area_modulation", "each canopy's start estimated", 2,
                             note="no refit converged (from ...)")
    for trial in (kept, failed):
        back = RefinementTrial.from_dict(_again(trial.as_dict()))
        assert (back.step, back.effect, back.change, back.tried, back.kept, back.note) == (
            trial.step, trial.effect, trial.change, trial.tried, trial.kept, trial.note)
        assert back.lr == trial.lr and back.estimates == trial.estimates
    assert "added_mass_exponent = 5.718" in str(kept) and "kept over 1" in str(kept)
    assert str(failed).endswith("no refit converged (from ...)")


def test_a_term_selection_reads_back_as_written() -> None:
    found = TermSelection(0, LikelihoodRatio(1009.64, 3),
                          {"drag_term[log_dynamic_pressure]": (-0.09727, 0.0031)},
                          LikelihoodRatio(1007.53, 1),
                          ["log_dynamic_pressure_squared (|z| 0.4)", "log_density (|z| 1.4)"])
    back = TermSelection.from_dict(_again(found.as_dict()))
    assert back.gate == found.gate and back.lr == found.lr
    assert back.selected == found.selected and back.dropped == found.dropped
    text = str(back)
    assert "drag_term[log_dynamic_pressure] = -0.0973 ± 0.0031" in text  # to its sigma
    assert "dropped log_dynamic_pressure_squared (|z| 0.4), log_density (|z| 1.4)" in text
    none = TermSelection(3, LikelihoodRatio(2.1, 3), note="no term is needed")
    assert not none.found and str(none).endswith("no term is needed")
