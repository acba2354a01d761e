"""Every name a manifest may use is documented: each atmosphere kind and sensor kind of
the schemas, and each effect of the registry, is named in the README's "A test folder"
section and in docs/test-folder.md; and the page's effect tables agree with the code.

For each registered effect the page has a section (### `name`) whose option table
lists exactly the effect's constructor options (with the class's defaults where the
page gives a number), and whose parameter table lists exactly the parameter bases the
effect declares on the built-in problems, with their SI unit, their default (a number
where the code's default is the same on every problem) and whether the fit estimates
them by default; the options agree with what `cpas-ocp effects` prints, and the page
calls exactly its starred effects the baseline.  Every field of the manifest, series and
model schemas, and every unit the converter accepts, is on the page too.  A new
atmosphere, sensor kind, effect, option, parameter or field without documentation fails
here.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.flight_test import flight_test_from_manifest
from cpas_ocp.io.problems import load_problem, problem_names
from cpas_ocp.physics.effects.registry import BASELINE, BUILTIN, EffectType
from cpas_ocp.physics.parameters import Parameter, split_name
from cpas_ocp.physics.units import FACTORS

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGE = ROOT / "docs" / "test-folder.md"
SCHEMAS = ROOT / "data_schemas"


def section(text: str, heading: str) -> str:
    """The text under the line `heading` up to the next heading of the same level."""
    level = heading.split(" ")[0]
    start = text.index(heading + "\n")
    rest = text[start + len(heading) + 1:]
    end = re.search(rf"^{level} ", rest, re.MULTILINE)
    return rest[: end.start()] if end else rest


def atmosphere_kinds() -> list[str]:
    schema = json.loads((SCHEMAS / "manifest.schema.json").read_text())
    return schema["properties"]["atmosphere"]["properties"]["model"]["enum"]


def sensor_kinds() -> list[str]:
    return json.loads((SCHEMAS / "series.schema.json").read_text())["properties"]["kind"]["enum"]


def documented_names() -> list[str]:
    return list(dict.fromkeys([*atmosphere_kinds(), *sensor_kinds(), *BUILTIN]))


@pytest.mark.parametrize("name", documented_names())
def test_every_name_is_in_the_readme_and_the_reference(name: str) -> None:
    readme = section(README.read_text(), "## A test folder")
    assert f"`{name}`" in readme, f"README's 'A test folder' section does not name {name}"
    assert f"`{name}`" in PAGE.read_text(), f"docs/test-folder.md does not name {name}"


def test_the_readme_points_to_the_reference() -> None:
    readme = README.read_text()
    assert "docs/test-folder.md" in section(readme, "## A test folder")
    assert "[docs/test-folder.md](docs/test-folder.md)" in section(readme, "## Documentation")


def table(text: str, first_header: str) -> list[list[str]]:
    """The body rows (cells stripped) of the Markdown table whose first header cell is
    `first_header`; [] where there is none."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == first_header:
            rows = []
            for row in lines[i + 2:]:
                if not row.startswith("|"):
                    break
                rows.append([c.strip() for c in re.split(r"(?<!\\)\|", row.strip().strip("|"))])
            return rows
    return []


def number(cell: str) -> float | None:
    try:
        return float(cell.replace(",", ""))
    except ValueError:
        return None


def option_defaults(entry: EffectType) -> dict[str, object]:
    """Each option's default: the registry's preset, else the class's own."""
    if dataclasses.is_dataclass(entry.cls):
        own = {f.name: f.default for f in dataclasses.fields(entry.cls)
               if f.init and f.default is not dataclasses.MISSING}
    else:
        own = {}
    return {name: entry.preset.get(name, own.get(name)) for name in entry.options()}


def problem_test(name: str):
    """The built-in problem's test, its series planned at 10 Hz and one observed event per
    stage of a canopy that deploys in the phase (a mortar fire, then a disreef into each
    later stage; a canopy open at the start has none) and the standard
    atmosphere (no parameter depends on the air, and a table's file is not at hand):
    enough for every effect to declare its parameters, without simulating."""
    problem = load_problem(name)
    manifest = json.loads(json.dumps(problem.manifest))
    manifest["atmosphere"] = {"model": "standard"}
    manifest["events"] = [
        {"name": "mortar_fire" if k == 0 else "disreef", "parachute": c["name"],
         **({"stage": stage} if k else {}),
         "time": {"value": 1.0 + 2.0 * k, "unit": "s"}, "sigma": {"value": 0.1, "unit": "s"}}
        for c in manifest["parachutes"] if not c.get("open_at_start")
        for k, stage in enumerate(c["stages"])]
    t_end = float(problem.simulation["t_end"])
    series = {s["name"]: pd.DataFrame({"time": np.arange(0.0, t_end, 0.1)})
              for s in manifest["sensors"]}
    return flight_test_from_manifest(manifest, Path(name), series=series)


@pytest.fixture(scope="module")
def declared() -> dict[str, list[Parameter]]:
    """Effect name -> the parameters it declares on every built-in problem."""
    tests = [problem_test(name) for name in problem_names()]
    return {name: [p for test in tests for p in entry.build({}, "registry", name)
                   .parameters(test)] for name, entry in BUILTIN.items()}


@pytest.mark.parametrize("name", list(BUILTIN))
def test_each_effects_options_are_documented(name: str) -> None:
    text = section(PAGE.read_text(), f"### `{name}`")
    entry = BUILTIN[name]
    rows = table(text, "option")
    if not entry.options():
        assert "Options: none." in text and not rows, name
        return
    assert [r[0].strip("`") for r in rows] == entry.options(), name
    defaults = option_defaults(entry)
    for option, default, *_ in rows:
        value = number(default)
        if value is not None:
            assert value == pytest.approx(float(defaults[option.strip("`")])), (name, option)


@pytest.mark.parametrize("name", list(BUILTIN))
def test_each_effects_parameters_are_documented(name: str, declared) -> None:
    text = section(PAGE.read_text(), f"### `{name}`")
    params = declared[name]
    rows = table(text, "parameter")
    if not rows:
        assert "Parameters: none." in text and not params, name
        return
    by_base: dict[str, list[Parameter]] = {}
    for p in params:
        by_base.setdefault(split_name(p.name)[0], []).append(p)
    documented = {split_name(r[0].strip("`").replace("[k]", "[0]"))[0]: r for r in rows}
    assert set(documented) == set(by_base), name
    for base, (_, unit, default, estimated) in documented.items():
        found = by_base[base]
        assert {p.unit for p in found} == {unit}, (name, base)
        defaults = {round(p.default, 9) for p in found}
        value = number(default)
        if value is not None:
            assert all(d == pytest.approx(value) for d in defaults), (name, base, defaults)
        elif len(defaults) == 1:
            # Described in words, a default that is one number on every problem is printed.
            assert f"{next(iter(defaults)):g}" in re.findall(r"[-\d.]+", default), (name, base)
        free = {p.estimable and p.free_by_default for p in found}
        assert free == {estimated == "free"}, (name, base)


def schema_fields(node: object, found: set[str] | None = None) -> set[str]:
    """Every property name a JSON Schema (or part of one) defines, through allOf, items,
    if/then and nested objects ($defs left out: they hold units, not fields)."""
    found = set() if found is None else found
    if isinstance(node, dict):
        for key, child in node.items():
            if key == "properties":
                found.update(child)
            if key != "$defs":
                schema_fields(child, found)
    elif isinstance(node, list):
        for child in node:
            schema_fields(child, found)
    return found


@pytest.mark.parametrize("schema", ["manifest.schema.json", "series.schema.json",
                                    "model.schema.json"])
def test_every_schema_field_is_documented(schema: str) -> None:
    fields = schema_fields(json.loads((SCHEMAS / schema).read_text()))
    # `value` and `unit` make every quantity; `$schema`-like keys are not fields.
    missing = sorted(f for f in fields - {"value", "unit"} if f"`{f}`" not in PAGE.read_text())
    assert not missing, f"docs/test-folder.md does not describe {missing} of {schema}"


def test_every_unit_is_in_the_units_table() -> None:
    listed = " ".join(" ".join(row) for row in table(PAGE.read_text(), "dimension"))
    missing = sorted({f"{dim}: {u}" for dim, units in FACTORS.items() for u in units
                      if u and f"`{u}`" not in listed})
    assert not missing


def test_the_page_matches_the_effects_command(capsys) -> None:
    """`cpas-ocp effects` lists each effect with its options and marks the baseline set;
    the page gives the same options and calls exactly the baseline effects Baseline."""
    assert main(["effects"]) == 0
    listing = capsys.readouterr().out
    entries = re.findall(r"^([* ]) (\w+)\s.*\n\s+options: (.*)$", listing, re.MULTILINE)
    assert [name for _, name, _ in entries] == list(BUILTIN)
    page = PAGE.read_text()
    for mark, name, options in entries:
        text = section(page, f"### `{name}`")
        listed = [r[0].strip("`") for r in table(text, "option")]
        assert listed == ([] if options.strip() == "-" else options.split(", ")), name
        assert ("Baseline." in text) == (mark == "*") == (name in BASELINE), name
