"""Property-based: any corruption of a manifest or a series is valid input or one line, exit 2.

Hypothesis picks a node of the `fbcp` manifest (a value, a list, an object) and
deletes it or replaces it with a value of another kind or an extreme one
(NaN and Infinity literals, 1e300, negative numbers, empty strings and
containers).  `cpas-ocp reduce` then either succeeds (the change was valid)
or exits 2 with one line naming the manifest, with no traceback and nothing
written; never an internal error, never a crash.  The example count is kept
small here; `benchmarks/fuzz_inputs.py` runs the long profile.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpas_ocp.cli import main
from tests.corruption import EXAMPLES, SEEDED, assert_contract, corrupted_document, corrupted_lines


@pytest.fixture(scope="module")
def fbcp(problem_folder) -> Path:
    return problem_folder("fbcp", 1)


def check_contract(folder: Path, out: Path, capsys) -> None:
    """The contract of a command reading `folder`: exit 0, or exit 2 with one line naming a
    file of the folder, no traceback and nothing written."""
    code = main(["reduce", str(folder), "--out", str(out)])
    assert_contract(code, capsys.readouterr().err.strip(), str(folder), out)


@settings(max_examples=EXAMPLES, deadline=None, derandomize=not SEEDED,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_corrupted_manifest_is_valid_or_one_line_exit_2(data, fbcp, tmp_path, capsys):
    manifest = json.loads((fbcp / "manifest.json").read_text())
    document = corrupted_document(data, manifest)
    work = tmp_path / f"case{abs(hash(json.dumps(document, sort_keys=True)))}"
    folder = work / "test"
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(fbcp, folder)
    (folder / "manifest.json").write_text(json.dumps(document))
    check_contract(folder, work / "out", capsys)


@settings(max_examples=EXAMPLES, deadline=None, derandomize=not SEEDED,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_corrupted_series_is_valid_or_one_line_exit_2(data, fbcp, tmp_path, capsys):
    """A sensor CSV with a cell replaced, rows dropped or repeated, its header damaged, or
    cut off mid-line: valid input or one line with exit 2."""
    files = sorted(p.name for p in fbcp.glob("*.csv"))
    name = data.draw(st.sampled_from(files), label="file")
    lines = corrupted_lines(data, (fbcp / name).read_text().splitlines())
    work = tmp_path / f"case{abs(hash((name, tuple(lines))))}"
    folder = work / "test"
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(fbcp, folder)
    (folder / name).write_text("\n".join(lines) + "\n")
    check_contract(folder, work / "out", capsys)
