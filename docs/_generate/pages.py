"""The documentation site's generated pages: the command reference from the argument parser,
the file formats from the JSON Schemas in data_schemas/, and each tutorial page from its
script (jupytext percent format, run by the suite).  `gen_pages.py` writes them into the
site at build time (mkdocs-gen-files); nothing generated is kept in the repository."""

from __future__ import annotations

import argparse
import ast
import json
import math
import re
from pathlib import Path
from typing import Any

from cpas_ocp.cli import arguments

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "data_schemas"
TUTORIALS = ROOT / "docs" / "tutorials"
RESULTS = ROOT / "benchmarks" / "results"  # each benchmark's latest result (harness.report)


def _cell(text: object) -> str:
    """`text` fit for one cell of a markdown table."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _summaries(parser: argparse.ArgumentParser) -> dict[str, str]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {c.dest: c.help or "" for c in action._choices_actions}


def command_reference() -> str:
    """One section per command: what it does, its usage line and a table of its arguments
    (name, what it is, default), all from `cpas_ocp.cli.arguments.parser`."""
    parser = arguments.parser()
    summaries = _summaries(parser)
    out = ["# Command reference", "",
           "Generated from the command line's own parser: what `cpas-ocp COMMAND --help` "
           "prints, every command on one page. Bad input exits 2 with one line naming the "
           "file, the field and the expectation; a fit that is not a result exits 4.", ""]
    for name, sub in _subcommands(parser).items():
        usage = " ".join(sub.format_usage().split())
        usage = usage.removeprefix("usage: ")
        out += [f"## `{name}`", "", summaries.get(name, "").rstrip(".") + ".", "",
                f"```\n{usage}\n```", ""]
        rows = []
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            flags = ", ".join(f"`{f}`" for f in action.option_strings) or f"`{action.dest}`"
            default = action.default
            shown = ("" if default in (None, False, [], argparse.SUPPRESS)
                     or action.required or not action.option_strings else f"`{default}`")
            rows.append(f"| {flags} | {_cell(action.help or '')} | {shown} |")
        if rows:
            out += ["| argument | what it is | default |", "|---|---|---|", *rows, ""]
    return "\n".join(out) + "\n"


def _link(ref: str) -> str:
    """A schema reference as a link: to a definition of this page ("#/$defs/length"), to
    another format's page ("model.schema.json"), or to a definition there."""
    where, _, pointer = ref.partition("#")
    name = pointer.rsplit("/", 1)[-1] if pointer else ""
    page = where.rsplit("/", 1)[-1].replace(".schema.json", ".md") if where else ""
    label = name or page.removesuffix(".md")
    return f"[{label}]({page}{'#' + name.lower() if name else ''})"


def _type(schema: dict[str, Any]) -> str:
    if "$ref" in schema:
        return _link(schema["$ref"])
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if "enum" in schema:
        return "one of " + ", ".join(f"`{json.dumps(v)}`" for v in schema["enum"])
    kind = schema.get("type", "")
    if isinstance(kind, list):
        kind = " or ".join(kind)
    if kind == "array" and isinstance(schema.get("items"), dict):
        return f"array of {_type(schema['items'])}"
    if not kind and ("oneOf" in schema or "anyOf" in schema):
        return " or ".join(_type(s) for s in schema.get("oneOf", schema.get("anyOf", [])))
    return kind or "any"


def _properties(schema: dict[str, Any], level: int, title: str) -> list[str]:
    """A table of `schema`'s properties, then a section per object property that has
    properties of its own."""
    props = schema.get("properties", {})
    if not props:
        return []
    required = set(schema.get("required", []))
    out = [f"{'#' * level} {title}", ""]
    if schema.get("description") and level > 2:
        out += [schema["description"], ""]
    out += ["| field | type | required | what it is |", "|---|---|---|---|"]
    nested = []
    for name, sub in props.items():
        out.append(f"| `{name}` | {_cell(_type(sub))} | {'yes' if name in required else ''} "
                   f"| {_cell(sub.get('description', ''))} |")
        if sub.get("type") == "object" and sub.get("properties"):
            nested.append((name, sub))
        elif isinstance(sub.get("items"), dict) and sub["items"].get("properties"):
            nested.append((f"{name}[]", sub["items"]))
    out.append("")
    for name, sub in nested:
        out += _properties(sub, min(level + 1, 4), f"`{title.strip('`')}.{name}`"
                           if level > 2 else f"`{name}`")
    return out


def format_page(path: Path) -> str:
    """The format of one schema of data_schemas/: its title and description, its fields
    (type, required, what each is), nested objects and shared definitions."""
    schema = json.loads(path.read_text())
    out = [f"# {schema.get('title', path.stem)}", "",
           f"Schema `data_schemas/{path.name}` (JSON Schema, generated page).", ""]
    if schema.get("description"):
        out += [schema["description"], ""]
    out += _properties(schema, 2, "Fields")
    for name, sub in schema.get("$defs", {}).items():
        if sub.get("properties"):
            out += _properties({**sub, "description": sub.get("description", "")}, 2, name)
        else:
            out += [f"## {name}", "", f"{_type(sub)}. {sub.get('description', '')}", ""]
    return "\n".join(out) + "\n"


def format_index(paths: list[Path]) -> str:
    """The list of formats, each with its schema's title."""
    rows = [f"- [{json.loads(p.read_text()).get('title', p.stem)}]"
            f"({p.stem.replace('.schema', '')}.md) (`{p.name}`)" for p in paths]
    return "\n".join(["# File formats", "",
                      "Every input file cpas-ocp reads is checked against a JSON Schema in "
                      "`data_schemas/`; these pages are generated from them.", "", *rows]) + "\n"


def tutorial_page(path: Path) -> str:
    """The page of a tutorial script in jupytext's percent format: its markdown cells as
    text, its code cells as Python blocks (the header block left out)."""
    text = path.read_text()
    if text.startswith("# ---"):
        text = text.split("# ---", 2)[2]
    out = []
    for cell in text.split("# %%")[1:]:
        head, _, body = cell.partition("\n")
        if head.strip() == "[markdown]":
            out.append("\n".join(line[2:] if line.startswith("# ") else line.lstrip("#")
                                 for line in body.strip().splitlines()))
        elif body.strip():
            out.append(f"```python\n{body.strip()}\n```")
    name = path.relative_to(ROOT).as_posix()
    out.append(f"*This page is the script `{name}`; the suite runs it as printed.*")
    return "\n\n".join(out) + "\n"


def _case(value: Any) -> bool:
    """One case of a table: an object of plain figures (no objects or lists in it)."""
    return isinstance(value, dict) and bool(value) and not any(
        isinstance(x, dict | list) for x in value.values())


def _is_table(value: Any) -> bool:
    """A result that reads as a table: one written by `harness.table` (``{"columns": [...],
    "rows": [[...], ...]}``), or records: two or more named cases (`_case`,
    ``{"drogue": {"samples": 7209, ...}, "fbcp": {...}}``), or a list of two or more cases
    (runs in order)."""
    if isinstance(value, list):
        return len(value) >= 2 and all(_case(v) for v in value)
    if not isinstance(value, dict):
        return False
    if set(value) == {"columns", "rows"}:
        return True
    return len(value) >= 2 and all(_case(v) for v in value.values())


def _as_table(value: dict[str, Any] | list[dict[str, Any]]) -> dict[str, Any]:
    """`value` (`_is_table`) as columns and rows; records take a column per figure any case
    has, a case's name first (a list's runs have none)."""
    if isinstance(value, list):
        columns = list(dict.fromkeys(k for v in value for k in v))
        return {"columns": columns, "rows": [[run.get(c) for c in columns] for run in value]}
    if set(value) == {"columns", "rows"}:
        return value
    columns = list(dict.fromkeys(k for v in value.values() for k in v))
    return {"columns": ["", *columns],
            "rows": [[name, *(case.get(c) for c in columns)] for name, case in value.items()]}


def _flatten(value: Any, key: str = "") -> list[tuple[str, Any]]:
    """(dotted key, value) for every leaf of a result; short lists of numbers kept whole,
    a table (`_is_table`) as one leaf."""
    if _is_table(value):
        return [(key, value)]
    if isinstance(value, dict):
        # Cases beside other figures (``{"seeds": 7, "hierarchical": {...}, "nested": {...}}``)
        # are read as one table where two or more of them hold the same figures.
        flat = {k: v for k, v in value.items() if _case(v)}
        shapes = [tuple(v) for v in flat.values()]
        cases = {k: v for k, v in flat.items() if shapes.count(tuple(v)) >= 2}
        rows = [(key, cases)] if cases else []
        return rows + [row for k, v in value.items() if k not in cases
                       for row in _flatten(v, f"{key}.{k}" if key else k)]
    if isinstance(value, list) and len(value) > 6 and all(isinstance(v, dict) for v in value):
        return [(key, f"{len(value)} rows (in the JSON)")]
    return [(key, value)]


def _shown(value: Any) -> str:
    """A figure as the table prints it: numbers to 4 significant digits."""
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_shown(v) for v in value) + "]"
    return "—" if value is None else str(value)


def _purpose(name: str) -> str:
    """The first paragraph of the benchmark script's docstring (what it measures); a
    record named ``SCRIPT-CASE`` is one of that script's runs."""
    script = ROOT / "benchmarks" / f"{name.split('-')[0]}.py"
    if not script.is_file():
        return ""
    doc = ast.get_docstring(ast.parse(script.read_text())) or ""
    return " ".join(doc.split("\n\n")[0].split())


def _markdown_table(value: dict[str, Any] | list[dict[str, Any]]) -> list[str]:
    """A table result (`_is_table`) as a markdown table, each number to 4 significant
    digits."""
    table = _as_table(value)
    return [f"| {' | '.join(_cell(c) for c in table['columns'])} |",
            "|" + "---|" * len(table["columns"]),
            *(f"| {' | '.join(_cell(_shown(v)) for v in row)} |" for row in table["rows"]), ""]


def _provenance(result: dict[str, Any]) -> str:
    """Where a result comes from: the revision, date, machine and load of its run."""
    m = result.get("machine", {})
    load = result.get("load_average") or []
    return (f"Revision `{result.get('revision', 'unknown')}`, {result.get('date', '')}, "
            f"{m.get('cpus', result.get('cpus', '?'))} CPUs, {m.get('platform', '')}, "
            f"Python {m.get('python', '?')}, CasADi {m.get('casadi', '?')}; load average "
            f"{', '.join(f'{v:.1f}' for v in load)}.")


def _command(result: dict[str, Any]) -> str:
    return result.get("command") or f"python benchmarks/{result['benchmark']}.py"


def _figures(result: dict[str, Any]) -> list[str]:
    """A result's figures: its tables (`_is_table`) each under its name, then the other
    figures as one table of name and value."""
    if _is_table(result["results"]):
        return _markdown_table(result["results"])
    leaves = _flatten(result["results"])
    out: list[str] = []
    for key, value in leaves:
        if _is_table(value):
            out += [*([f"*{key}*", ""] if key else []), *_markdown_table(value)]
    rest = [(k, v) for k, v in leaves if not _is_table(v)]
    if rest:
        out += ["| figure | value |", "|---|---|",
                *(f"| `{k}` | {_cell(_shown(v))} |" for k, v in rest), ""]
    return out


RESULT_MARK = re.compile(r"^<!-- result: ([a-z0-9_]+(?:-[a-z0-9_]+)*)((?:\.[A-Za-z0-9_]+)*) -->$",
                         re.MULTILINE)


def result_block(name: str, part: str = "") -> str:
    """A benchmark's latest recorded result as the validation page shows it in place: its
    tables and figures (only those under the dotted key `part`, where given), then the
    command and run that produced them."""
    path = RESULTS / f"{name}.json"
    where = f"docs/validation.md: <!-- result: {name}{part} -->"
    if not path.is_file():
        raise FileNotFoundError(f"{where} names no recorded result (run python "
                                f"benchmarks/{name}.py)")
    result = json.loads(path.read_text())
    figures = result["results"]
    for key in filter(None, part.split(".")):
        if not isinstance(figures, dict) or key not in figures:
            raise KeyError(f"{where}: the result has no {key!r}")
        figures = figures[key]
    if not isinstance(figures, dict):
        figures = {part.rsplit(".", 1)[-1]: figures}
    return "\n".join([*_figures({"results": figures}),
                      f"*Generated from `benchmarks/results/{name}.json`: `{_command(result)}`. "
                      f"{_provenance(result)}*", ""])


def validation_page(text: str) -> str:
    """docs/validation.md with each ``<!-- result: NAME -->`` line replaced by that
    benchmark's latest recorded result (`result_block`): the tables are rendered from the
    JSON at every build, so rerunning the benchmark is what changes them."""
    return RESULT_MARK.sub(lambda m: result_block(m.group(1), m.group(2)), text)


def results_page(paths: list[Path]) -> str:
    """The measured results: for each benchmark's latest result (benchmarks/results/*.json,
    written by `harness.report`), what it measures, the revision, date and machine it ran
    on and the command that ran it, and its figures as a table.  Rerunning a benchmark
    rewrites its result; the site's next build shows it."""
    out = ["# Measured results", "",
           "Each table is the latest run of a benchmark script, rendered from its JSON result "
           "(`benchmarks/results/NAME.json`) when the site is built: rerun the command shown "
           "and the table follows. Timings are wall-clock on the machine named, under the "
           "load average given; ratios against a baseline run in the same script are what "
           "carry from one machine to another.", ""]
    if not paths:
        out.append("No benchmark has recorded a result yet.")
    for path in paths:
        result = json.loads(path.read_text())
        name = result["benchmark"]
        out += [f"## {name}", "", _purpose(name), "", _provenance(result), "",
                f"```\n{_command(result)}\n```", "", *_figures(result)]
    return "\n".join(out) + "\n"
