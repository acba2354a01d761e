"""The plug-in author's guide works as written: its worked example, taken from
docs/plugins.md, is a plug-in that simulates, fits and tests first time.

FBCP data are simulated with the guide's drag-area growth after full open
(1 % per second, about 3 % by the phase's end).  `cpas-ocp compare` of the
manifest's model against the guide's model file must find the growth
significant (p < 1e-6 on its two parameters), fit to the noise, and
recover it within 4 sigma.  The same file with its `forces` hook misspelt is refused
with exit code 2 and a line naming the file and the hook.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.registry import BASELINE, load_plugin

pytestmark = pytest.mark.slow

GUIDE = Path(__file__).parents[2] / "docs" / "plugins.md"
GROWTH = 0.01  # 1/s


def guide_example() -> tuple[str, str]:
    """The worked example's file name and source, as the guide prints them."""
    found = re.search(r"<!-- plugin-example: (\S+) -->\s*```python\n(.*?)```", GUIDE.read_text(),
                      re.DOTALL)
    assert found is not None, "the guide's worked example is marked plugin-example"
    return found.group(1), found.group(2)


@pytest.fixture(scope="module")
def comparison(tmp_path_factory) -> tuple[dict, dict]:
    """The truth and the comparison (json) of baseline against the guide's model."""
    root = tmp_path_factory.mktemp("guide")
    name, source = guide_example()
    plugin = root / name
    plugin.write_text(source)
    growth = load_plugin(plugin)["drag_area_growth"].build({}, str(plugin), "test")
    problem = load_problem("fbcp")
    rates = {f"growth_rate[{c['name']}]": GROWTH for c in problem.manifest["parachutes"]}
    base = baseline_effects()
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **rates}),
                     root / "test", 2, effects=[base[0], growth, *base[1:]])
    (root / "test" / "truth.json").unlink()
    (root / "growth.json").write_text(json.dumps(
        {"effects": [BASELINE[0], "drag_area_growth", *BASELINE[1:]], "plugins": [name]}))
    assert main(["compare", str(root / "test"), "--model", "manifest",
                 "--model", str(root / "growth.json"), "--out", str(root / "comparison")]) == 0
    return rates, json.loads((root / "comparison" / "comparison.json").read_text())


def test_the_guides_example_is_recovered_and_significant(comparison) -> None:
    rates, result = comparison
    lr = result["likelihood_ratio"]
    assert lr["dof"] == len(rates) and lr["p_value"] < 1e-6
    before, after = result["models"]["manifest"], result["models"]["growth"]
    n = after["n"]
    # The guide's model fits within the noise's spread of chi^2/n, sqrt(2/n).
    assert before["chi_square"] > after["chi_square"]
    assert after["chi_square"] / n < 1.0 + 4.0 * (2.0 / n) ** 0.5
    for name, truth in rates.items():
        assert abs(after["parameters"][name] - truth) < 4.0 * after["std"][name], name


def test_a_misspelt_hook_in_the_guides_example_is_refused(tmp_path, capsys) -> None:
    name, source = guide_example()
    bad = tmp_path / name
    bad.write_text(source.replace("def forces(", "def force("))
    assert main(["effects", "--plugin", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(bad) in err and "DragAreaGrowth.force" in err and "'forces'" in err
