"""A manifest's `model` block (or a model file) chooses the effects and what is estimated."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import load_model_file, model_block, spec_from_effects, spec_of_test
from cpas_ocp.physics.effects import AddedMass, DragLawTerms, ElasticRiser, baseline_effects
from cpas_ocp.physics.effects.registry import BASELINE
from cpas_ocp.physics.units import FT

FULL = ["canopy_inflation", "forebody_drag", {"effect": "elastic_riser", "frequency": 12.0},
        "added_mass", "drag_scale", "loadcell_scale", "gps", "imu", "load_cell"]


def _with_model(src: Path, dest: Path, block: dict) -> Path:
    shutil.copytree(src, dest)
    path = dest / "manifest.json"
    manifest = json.loads(path.read_text())
    manifest["model"] = block
    path.write_text(json.dumps(manifest))
    return dest


def test_no_block_is_the_baseline(problem_folder) -> None:
    spec = spec_of_test(load_test(problem_folder("fbcp", 1)))
    assert spec.effect_names == list(BASELINE)
    model = spec.model(load_test(problem_folder("fbcp", 1)))
    assert "CdS_V" not in spec.free_names(model)
    assert spec.fixed_values(model) == {}


def test_block_sets_effects_options_fixed_and_free(problem_folder, tmp_path) -> None:
    block = {"effects": FULL, "free": ["CdS_V"],
             "fix": {"riser_damping_ratio[fbcp1]": 0.25,
                     "CdS[fbcp1,stage1]": {"value": 10.0, "unit": "ft^2"},
                     "t_start[fbcp2,stage1]": {"value": 850.0, "unit": "ms"}}}
    test = load_test(_with_model(problem_folder("fbcp", 1), tmp_path / "t", block))
    spec = spec_of_test(test)
    model = spec.model(test)
    assert spec.effect_names == [e if isinstance(e, str) else e["effect"] for e in FULL]
    riser = next(e for e in spec.effects if isinstance(e, ElasticRiser))
    assert riser.frequency == 12.0
    assert model.parameter("riser_period[fbcp1]").default == pytest.approx(1.0 / 12.0)
    fixed = spec.fixed_values(model)
    assert fixed["CdS[fbcp1,stage1]"] == pytest.approx(10.0 * FT**2)
    assert fixed["t_start[fbcp2,stage1]"] == pytest.approx(0.85)
    free = spec.free_names(model)
    assert "CdS_V" in free and "riser_damping_ratio[fbcp1]" not in free
    assert "riser_damping_ratio[fbcp2]" in free and "added_mass_factor[fbcp1]" in free


def test_fixed_shape_is_held_by_the_reduction(problem_folder, tmp_path) -> None:
    """`cpas-ocp reduce --model FILE`: the curve fit keeps a fixed expopen and refits the rest."""
    folder = problem_folder("fbcp", 1)
    model_file = tmp_path / "expopen1.json"
    model_file.write_text(json.dumps({"fix": {"expopen[fbcp1,stage1]": 1.0}}))
    assert load_model_file(model_file).effect_names == list(BASELINE)
    assert main(["reduce", str(folder), "--out", str(tmp_path / "free")]) == 0
    assert main(["reduce", str(folder), "--out", str(tmp_path / "held"),
                 "--model", str(model_file)]) == 0
    free = json.loads((tmp_path / "free" / "initial_guess.json").read_text())["parameters"]
    held = json.loads((tmp_path / "held" / "initial_guess.json").read_text())["parameters"]
    assert held["expopen[fbcp1,stage1]"]["value"] == 1.0
    assert abs(free["expopen[fbcp1,stage1]"]["value"] - 1.0) > 0.2
    # The fill constant compensates for the held exponent; the other canopy is untouched.
    assert held["n_p[fbcp1,stage1]"]["value"] != pytest.approx(free["n_p[fbcp1,stage1]"]["value"],
                                                                rel=0.02)
    assert held["n_p[fbcp2,stage1]"]["value"] == pytest.approx(free["n_p[fbcp2,stage1]"]["value"])


BAD_BLOCKS = {
    "unknown effect": ({"effects": ["canopy_inflation", "wake_deficitt"]}, "model.effects[1]"),
    "unknown option": (
        {"effects": ["canopy_inflation", {"effect": "elastic_riser", "stiffness": 1}]},
        "model.effects[1].stiffness"),
    "two riser models": ({"effects": ["canopy_inflation", "rigid_riser", "elastic_riser"]},
                         "model.effects"),
    "listed twice": ({"effects": ["canopy_inflation", "gps", "gps"]}, "model.effects[2]"),
    "fix unknown parameter": ({"fix": {"Ck[fbcp9,stage1]": 1.0}}, "model.fix.Ck[fbcp9,stage1]"),
    "fix in a wrong unit": ({"fix": {"CdS_V": {"value": 3.0, "unit": "lbf"}}},
                            "model.fix.CdS_V.unit"),
    "free unknown parameter": ({"free": ["CdS_X"]}, "model.free[0]"),
    "fixed and freed": ({"free": ["CdS_V"], "fix": {"CdS_V": 1.0}}, "model.fix.CdS_V"),
    "fixed outside its bounds": ({"fix": {"flyout_angle[fbcp1,stage1]": {"value": 90,
                                                                         "unit": "deg"}},
                                  "effects": ["canopy_inflation", "forebody_drag", "fly_out",
                                              "rigid_riser", "gps"]},
                                 "model.fix.flyout_angle[fbcp1,stage1]"),
    "wake deficit before the inflation": (
        {"effects": ["wake_deficit", "canopy_inflation", "rigid_riser", "gps"]}, "model.effects"),
    "no riser model": ({"effects": ["canopy_inflation", "gps", "imu", "load_cell"]},
                       "model.effects"),
    "option of the wrong type": ({"effects": ["canopy_inflation",
                                              {"effect": "wake_deficit", "prf": [1]}]},
                                 "model.effects[1]"),
    "option out of range": ({"effects": ["canopy_inflation",
                                         {"effect": "elastic_riser", "frequency": -1}]},
                            "model.effects[1]"),
    "not a list": ({"effects": "canopy_inflation"}, "model.effects"),
    "added mass before elastic risers": (
        {"effects": ["canopy_inflation", "forebody_drag", "added_mass", "elastic_riser",
                     "drag_scale", "loadcell_scale", "gps", "imu", "load_cell"]},
        "model.effects"),
    "plug-in that does not import": ({"plugins": ["broken.py"]}, "broken.py"),
    "missing plug-in": ({"plugins": ["absent.py"]}, "absent.py"),
    "plug-in outside the test folder": ({"plugins": ["../elsewhere.py"]}, "model.plugins[0]"),
    "plug-in at an absolute path": ({"plugins": ["/tmp/anywhere.py"]}, "model.plugins[0]"),
    "prior on an unknown parameter": ({"priors": {"CdS[fbcp9,stage1]": {"value": 2.0,
                                                                        "sigma": 0.1}}},
                                      "model.priors.CdS[fbcp9,stage1]"),
    "prior on a fixed parameter": ({"fix": {"CdS_V": 1.0},
                                    "priors": {"CdS_V": {"value": 1.0, "sigma": 0.1}}},
                                   "model.priors.CdS_V"),
    "prior without sigma": ({"priors": {"CdS[fbcp1,stage1]": {"value": 2.0}}},
                            "model.priors.CdS[fbcp1,stage1]"),
    "prior in a wrong unit": ({"priors": {"CdS[fbcp1,stage1]": {"value": 2.0, "sigma": 0.1,
                                                                "unit": "lbf"}}},
                              "model.priors.CdS[fbcp1,stage1].unit"),
    # A dimensionless factor fixed in a unit of acceleration: "g" also spells a load factor.
    "dimensionless factor in m/s^2": (
        {"effects": FULL,
         "fix": {"added_mass_factor[fbcp1]": {"value": 1, "unit": "m/s^2"}}},
        "model.fix.added_mass_factor[fbcp1].unit"),
    "dimensionless factor in g": (
        {"effects": FULL,
         "fix": {"added_mass_factor[fbcp1]": {"value": 1, "unit": "g"}}},
        "model.fix.added_mass_factor[fbcp1].unit"),
}


@pytest.mark.parametrize("case", list(BAD_BLOCKS))
def test_bad_model_block_is_one_line_exit_2(case, problem_folder, tmp_path, capsys) -> None:
    block, field = BAD_BLOCKS[case]
    folder = _with_model(problem_folder("fbcp", 1), tmp_path / "t", block)
    (folder / "broken.py").write_text("import cpas_ocp\nraise RuntimeError('half-written')\n")
    out = tmp_path / "report"
    code = main(["reconstruct", str(folder), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert field in err, err
    assert "Traceback" not in err
    assert not out.exists()


def test_model_file_errors_name_the_file(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"effects": ["gps"], "fixx": {}}))
    with pytest.raises(InputError, match=r"m\.json: model: Additional properties"):
        load_model_file(path)


def test_an_external_plug_in_runs_only_when_allowed(problem_folder, tmp_path, capsys) -> None:
    """A test folder may come from anyone, and a plug-in is code: one the manifest names from
    outside its folder runs only with --allow-external-plugins."""
    shutil.copy(Path(__file__).parents[1] / "plugins" / "breathing.py", tmp_path / "shared.py")
    folder = _with_model(problem_folder("fbcp", 1), tmp_path / "t", {"plugins": ["../shared.py"]})
    command = ["reduce", str(folder), "--out", str(tmp_path / "r")]
    assert main(command) == 2
    assert "--allow-external-plugins" in capsys.readouterr().err
    assert main([*command, "--allow-external-plugins"]) == 0


def test_a_refined_step_is_a_model_file_that_builds_it_again(tmp_path) -> None:
    """A discovery step's model file (`model_block`) names a refined or regressed effect with
    the options that make it so, and reading the file back builds the same effects."""
    base = baseline_effects()
    spec = spec_from_effects([base[0], DragLawTerms(terms=("log_dynamic_pressure",),
                                                    reference_pa=812.5), *base[1:],
                              AddedMass(exponent_free=True)])
    block = model_block(spec)
    assert {"effect": "added_mass", "exponent_free": True} in block["effects"]
    assert {"effect": "drag_law_terms", "terms": ["log_dynamic_pressure"],
            "reference_pa": 812.5} in block["effects"]
    path = tmp_path / "step_1.json"
    path.write_text(json.dumps(block))
    assert load_model_file(path).effects == spec.effects
