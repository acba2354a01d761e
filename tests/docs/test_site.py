"""The documentation site's generated pages (docs/_generate/pages.py): the command reference
holds every command and every option of the parser, each format page every field of its
schema, and each tutorial page its script's text and code; the tutorial scripts run as
printed.  The site itself is built in strict mode by CI (`mkdocs build --strict`)."""

from __future__ import annotations

import argparse
import json
import runpy
import sys
import tempfile
from pathlib import Path

import pytest

from cpas_ocp.cli import arguments

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_generate"))
import pages  # noqa: E402


def test_the_command_reference_holds_every_command_and_option() -> None:
    page = pages.command_reference()
    parser = arguments.parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        assert f"## `{name}`" in page, name
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            for flag in action.option_strings:
                assert f"`{flag}`" in page, (name, flag)
            if action.help:
                assert action.help.replace("|", "\\|") in page, (name, action.dest)


def _fields(schema: dict, prefix: str = "") -> list[str]:
    out = []
    for name, sub in schema.get("properties", {}).items():
        out.append(name)
        out += _fields(sub)
        if isinstance(sub.get("items"), dict):
            out += _fields(sub["items"])
    for sub in schema.get("$defs", {}).values():
        out += _fields(sub)
    return out


@pytest.mark.parametrize("path", sorted(pages.SCHEMAS.glob("*.schema.json")),
                         ids=lambda p: p.name)
def test_each_format_page_holds_every_field_of_its_schema(path: Path) -> None:
    page = pages.format_page(path)
    schema = json.loads(path.read_text())
    missing = [f for f in _fields(schema) if f"`{f}`" not in page]
    assert not missing, missing
    assert schema.get("title", path.stem) in page


def test_a_tutorial_page_is_its_script() -> None:
    page = pages.tutorial_page(ROOT / "docs" / "tutorials" / "drop_test.py")
    assert page.startswith("# A drop test, end to end\n")
    assert "```python\nimport tempfile" in page
    assert "rec = co.reconstruct(test)" in page
    assert "docs/tutorials/drop_test.py" in page
    assert "# %%" not in page and "\n# The legacy process's" not in page  # markdown unwrapped


TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.py"))


@pytest.mark.slow
@pytest.mark.parametrize("script", TUTORIALS, ids=lambda p: p.stem)
def test_each_tutorial_runs_as_printed(script: Path, monkeypatch, tmp_path, capsys) -> None:
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    ns = runpy.run_path(str(script), run_name="__main__")
    printed = capsys.readouterr().out
    if script.stem == "drop_test":
        assert ns["rec"].is_result and "holding Ck at 1.0 costs" in printed
        assert (ns["work"] / "report" / "report.html").is_file()
    elif script.stem == "planning":
        assert ns["design"].ranking and "%" in printed
    elif script.stem == "rocket_log":
        assert ns["rec"].is_result and "the main did not inflate" in printed
    elif script.stem == "campaign":
        assert ns["population"].groups and list((ns["work"] / "cases").glob("cases_*"))
    else:
        raise AssertionError(f"{script.name}: a tutorial this test does not check")


def test_a_benchmark_result_is_recorded_and_rendered(monkeypatch, tmp_path) -> None:
    """`harness.report` writes the benchmark's latest result with its revision, date and
    machine; the site's results page renders it as a table."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import harness

    monkeypatch.setattr(harness, "RESULTS", tmp_path)
    monkeypatch.setattr(sys, "argv", ["benchmarks/hierarchical_speed.py", "--tests", "4"])
    harness.parser(None, seed=1).parse_args(["--seed", "3"])
    harness.report("hierarchical_speed", speed_up=4.25, new_s=109.0,
                   failures={"old": "Maximum_Iterations_Exceeded"})
    [path] = tmp_path.glob("*.json")
    result = json.loads(path.read_text())
    assert result["seed"] == 3 and result["revision"] and result["machine"]["cpus"]
    page = pages.results_page([path])
    assert "## hierarchical_speed" in page and "| `speed_up` | 4.25 |" in page
    assert "| `failures.old` | Maximum_Iterations_Exceeded |" in page
    assert result["revision"] in page and result["date"] in page
    assert "benchmarks/hierarchical_speed.py --tests 4" in page
    assert "statistical test" in page  # what the benchmark measures, from its docstring
    harness.parser(None, seed=1).parse_args(["--no-record"])
    harness.report("hierarchical_speed", speed_up=1.0)
    assert json.loads(path.read_text())["results"]["speed_up"] == 4.25  # not rewritten


def test_each_validation_table_is_rendered_from_its_recorded_result() -> None:
    """Every `<!-- result: NAME[.part] -->` line of docs/validation.md names a recorded
    result, and the page the site shows holds that result's table, revision and date in its
    place."""
    text = (ROOT / "docs" / "validation.md").read_text()
    marks = pages.RESULT_MARK.findall(text)
    assert marks, "docs/validation.md renders no recorded result"
    page = pages.validation_page(text)
    assert "<!-- result:" not in page
    for name, _ in marks:
        result = json.loads((pages.RESULTS / f"{name}.json").read_text())
        assert f"Revision `{result['revision']}`, {result['date']}" in page, name
        assert f"benchmarks/results/{name}.json" in page, name


def test_a_scripts_runs_are_recorded_and_rendered_one_record_each(monkeypatch, tmp_path
                                                                   ) -> None:
    """A script run on several inputs (design_validation.py on each plan) records each run
    as SCRIPT-CASE: the marker names that record, and the page says what the script
    measures, from its docstring."""
    monkeypatch.setattr(pages, "RESULTS", tmp_path)
    (tmp_path / "design_validation-fbcp.json").write_text(json.dumps({
        "benchmark": "design_validation-fbcp", "revision": "abc1234567", "date": "d",
        "command": "python benchmarks/design_validation.py docs/plans/fbcp.json",
        "results": {"ranking": {"seeds": 50, "confirmed": True}}}))
    block = pages.validation_page("<!-- result: design_validation-fbcp.ranking -->")
    assert "| `confirmed` | True |" in block
    assert "benchmarks/results/design_validation-fbcp.json" in block
    assert pages._purpose("design_validation-fbcp").startswith("Benchmark:")


def test_cases_beside_other_figures_render_as_one_table(monkeypatch, tmp_path) -> None:
    """Cases holding the same figures become a table's rows (a case per row, a figure per
    column), a dotted part selects one branch, and a marker naming no result is an error
    that names the benchmark to run."""
    monkeypatch.setattr(pages, "RESULTS", tmp_path)
    (tmp_path / "coverage.json").write_text(json.dumps({
        "benchmark": "coverage", "revision": "abc1234567", "date": "d", "command": "c",
        "results": {"seeds": 7, "fit": {"a": {"covered": 0.95, "width": 0.06123456},
                                         "b": {"covered": 1.0, "width": 0.121}},
                    "runs": [{"rate": 100, "s": 0.7}, {"rate": 4000, "s": 2.4}]}}))
    block = pages.validation_page("<!-- result: coverage -->")
    assert "|  | covered | width |" in block and "| a | 0.95 | 0.06123 |" in block
    assert "| `seeds` | 7 |" in block
    assert "| rate | s |" in block and "| 4000 | 2.4 |" in block  # a list of runs
    part = pages.validation_page("<!-- result: coverage.fit.a -->")
    assert "| `covered` | 0.95 |" in part and "seeds" not in part
    with pytest.raises(FileNotFoundError, match=r"benchmarks/missing\.py"):
        pages.validation_page("<!-- result: missing -->")
    with pytest.raises(KeyError, match="no 'c'"):
        pages.validation_page("<!-- result: coverage.fit.c -->")


def test_the_validation_page_holds_no_table_written_by_hand() -> None:
    """Every table of docs/validation.md is rendered from a benchmark's record: the page's
    source holds markers and prose, and no table rows of its own."""
    text = (ROOT / "docs" / "validation.md").read_text()
    rows = [line for line in text.splitlines() if line.lstrip().startswith("|")]
    assert not rows, f"{len(rows)} hand-written table rows, the first: {rows[0]}"
