"""The diagnose and compare commands: reports on a clean fit, and one-line errors."""

from __future__ import annotations

import json

import pytest

from cpas_ocp.cli import main
from cpas_ocp.physics.effects.registry import BASELINE

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("argv, field", [
    (["diagnose", "{test}", "--out", "{out}", "--alpha", "2"], "--alpha"),
    (["diagnose", "{test}", "--out", "{out}", "--plugin", "{tmp}/absent.py"], "absent.py"),
    (["compare", "{test}", "--model", "manifest", "--out", "{out}"], "--model"),
    (["compare", "{test}", "--model", "manifest", "--model", "{tmp}/absent.json",
      "--out", "{out}"], "absent.json"),
])
def test_bad_arguments_are_one_line_exit_2(argv, field, problem_folder, tmp_path,
                                           capsys) -> None:
    names = {"test": str(problem_folder("fbcp", 1)), "out": str(tmp_path / "out"),
             "tmp": str(tmp_path)}
    code = main([a.format(**names) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and field in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


def test_compare_rigid_with_elastic_risers(problem_folder, tmp_path, capsys) -> None:
    """The baseline against the same set with elastic risers, on data from rigid risers.

    The rigid riser is nested in the elastic one at its null (the stiffest, critically
    damped riser), so the likelihood ratio is tested, chi-bar-squared on the four
    one-sided riser parameters: it must not be significant, and BIC must prefer the
    rigid risers (their four extra parameters buy almost nothing)."""
    elastic = [("elastic_riser" if e == "rigid_riser" else e) for e in BASELINE]
    (tmp_path / "rigid.json").write_text(json.dumps({"effects": list(BASELINE)}))
    (tmp_path / "elastic.json").write_text(json.dumps({"effects": elastic}))
    out = tmp_path / "cmp"
    code = main(["compare", str(problem_folder("fbcp", 1)), "--model",
                 str(tmp_path / "rigid.json"), "--model", str(tmp_path / "elastic.json"),
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    result = json.loads((out / "comparison.json").read_text())
    assert result["nesting"] == "rigid is nested in elastic"
    lr = result["likelihood_ratio"]
    assert lr["dof"] == 4 and lr["one_sided"] == 4
    assert lr["p_value"] > 0.01
    rigid, soft = result["models"]["rigid"], result["models"]["elastic"]
    assert soft["k"] == rigid["k"] + 4
    assert rigid["bic"] < soft["bic"]
    assert "BIC prefers rigid" in capsys.readouterr().out
    assert (out / "compare_riser_fbcp1.png").is_file() and (out / "comparison.md").is_file()


def test_compare_without_nesting_uses_the_criteria_only(problem_folder, tmp_path) -> None:
    """A model that drops an effect the other has, and adds another: neither is nested."""
    a = [*BASELINE, "gps_lag"]
    b = [*BASELINE, "imu_bias"]
    (tmp_path / "a.json").write_text(json.dumps({"effects": a}))
    (tmp_path / "b.json").write_text(json.dumps({"effects": b}))
    out = tmp_path / "cmp"
    assert main(["compare", str(problem_folder("fbcp", 1)), "--model", str(tmp_path / "a.json"),
                 "--model", str(tmp_path / "b.json"), "--out", str(out)]) == 0
    result = json.loads((out / "comparison.json").read_text())
    assert result["likelihood_ratio"] is None
    assert result["nesting"].startswith("neither model is nested")


def test_a_failing_plugin_candidate_is_the_plugins_error(problem_fit, tmp_path) -> None:
    """A user's effect whose code raises is the user's mistake, named by its file and hook
    (the command line's exit 2), not a candidate quietly left untested."""
    from cpas_ocp.discrepancy.score_test import score_test
    from cpas_ocp.errors import PluginError
    from cpas_ocp.io.model_spec import baseline_spec
    from cpas_ocp.physics.effects.registry import load_plugin
    (tmp_path / "bad.py").write_text(
        "from cpas_ocp.physics.effects import Effect\n"
        "from cpas_ocp.physics.parameters import Parameter\n\n\n"
        "class Bad(Effect):\n"
        "    name = 'bad_effect'\n\n"
        "    def parameters(self, test):\n"
        "        return [Parameter('bad_k', '1', 0.0, -1.0, 1.0)]\n\n"
        "    def null_values(self, test):\n"
        "        return {'bad_k': 0.0}\n\n"
        "    def forces(self, ctx):\n"
        "        raise RuntimeError('half-written physics')\n")
    fit, _, _ = problem_fit("fbcp", 1)
    with pytest.raises(PluginError) as raised:
        score_test(fit, baseline_spec(), load_plugin(tmp_path / "bad.py")["bad_effect"])
    assert str(raised.value) == (f"{tmp_path / 'bad.py'}: hook forces raised RuntimeError: "
                                 "half-written physics")
