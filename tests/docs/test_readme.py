"""The README is a front page for a person deciding and starting: at most 250 lines, no
commit hashes or dated timings (the history is in git), its quick-start test command the
one CI runs, its count of the suite's tests true whenever the whole suite runs, and its
demo and suite times those `benchmarks/quick_start.py` last measured."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()
MAX_LINES = 250
# seven or more hex digits with a letter and a digit among them: an abbreviated commit
COMMIT = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b")
DATE = re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b")
# the stated count may lag the suite by this share (a line per test added is not the point)
COUNT_SLACK = 0.05


def test_the_readme_is_a_front_page() -> None:
    lines = README.splitlines()
    assert len(lines) <= MAX_LINES, f"README has {len(lines)} lines; at most {MAX_LINES}"
    assert not COMMIT.search(README), COMMIT.search(README)
    assert not DATE.search(README), DATE.search(README)


def test_the_quick_start_test_command_is_the_one_ci_runs() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    command = "python -m pytest -q -n 2 --dist loadfile"
    assert command in README.split("## Quick start")[1].split("\n## ")[0]
    assert command in ci


def test_the_stated_test_count_is_the_suites(request: pytest.FixtureRequest) -> None:
    """Checked where the whole suite was collected (no -k or -m, every test folder)."""
    session = request.session
    option = request.config.option
    folders = {p.parent.name for p in (ROOT / "tests").glob("*/test_*.py")}
    collected = {Path(item.path).parent.name for item in session.items}
    if option.keyword or option.markexpr or not folders <= collected:
        pytest.skip("the count is checked when the whole suite runs")
    stated = re.search(r"\*\*The second command\*\* runs the whole suite on both cores: "
                       r"([\d,]+) tests", README)
    assert stated, "the README no longer states the suite's size where it did"
    count = int(stated.group(1).replace(",", ""))
    assert abs(count - len(session.items)) <= COUNT_SLACK * len(session.items), (
        f"README says {count} tests; the suite has {len(session.items)}")


# The README's times are rounded figures ("about 40 s", "about 9 minutes"): a stated time
# agrees with the measured one within this share of it, or within the rounding step.
TIME_SLACK = 0.15
QUICK_START = ROOT / "benchmarks" / "results" / "quick_start.json"


def test_the_stated_times_are_the_latest_measured() -> None:
    """The demo's and the suite's times in the README agree with the latest run of
    `benchmarks/quick_start.py` (benchmarks/results/quick_start.json): rerun it when the
    suite or the demo changes, and update the README where they disagree."""
    measured = json.loads(QUICK_START.read_text())["results"]
    demo = re.search(r"The demo\s+takes\s+about\s+(\d+)\s+s\b", README)
    suite = re.search(r"tests\s+in\s+about\s+(\d+)\s+minutes", README)
    assert demo and suite, "the README no longer states the demo's and the suite's times"
    demo_s = measured["demo"]["median_s"]
    assert abs(int(demo.group(1)) - demo_s) <= max(TIME_SLACK * demo_s, 5.0), (
        f"README: demo about {demo.group(1)} s; measured {demo_s:.0f} s")
    suite_min = measured["suite"]["wall_s"] / 60.0
    assert abs(int(suite.group(1)) - suite_min) <= max(TIME_SLACK * suite_min, 1.0), (
        f"README: suite about {suite.group(1)} minutes; measured {suite_min:.1f}")
