"""Corruptions of JSON documents and text tables, shared by the property-based input tests."""

from __future__ import annotations

import json
import math
import os
from typing import Any

from hypothesis import strategies as st

REPLACEMENTS = st.sampled_from([None, "", "x", "lbf", -1, 0, -1e300, 1e300, math.nan, math.inf,
                                True, [], {}, [1, 2], {"value": 1}, "../outside.csv"])
CELLS = st.sampled_from(["", "nan", "inf", "-inf", "1e300", "-1", "x", "0x1F", "1,2",
                         "\"", "\x00", "1e-300"])
# Examples per run: a dozen in the suite, more in benchmarks/fuzz_inputs.py, which also
# draws them from a given seed (the suite's are fixed: derandomised).
EXAMPLES = int(os.environ.get("CPAS_OCP_FUZZ_EXAMPLES", "12"))
SEEDED = "CPAS_OCP_FUZZ_SEED" in os.environ


def node_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to a node below the root."""
    out = []
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, child in items:
        out.append((*prefix, key))
        out += node_paths(child, (*prefix, key))
    return out


def corrupt(document: dict, path: tuple, replacement: Any, delete: bool) -> dict:
    """A copy of `document` with the node at `path` deleted or replaced."""
    copy = json.loads(json.dumps(document))
    parent = copy
    for key in path[:-1]:
        parent = parent[key]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = replacement
    return copy


def corrupted_document(data: st.DataObject, document: dict) -> dict:
    """`document` with one node, drawn by Hypothesis, deleted or replaced."""
    path = data.draw(st.sampled_from(node_paths(document)), label="path")
    delete = data.draw(st.booleans(), label="delete")
    replacement = data.draw(REPLACEMENTS, label="replacement")
    return corrupt(document, path, replacement, delete)


def corrupted_lines(data: st.DataObject, lines: list[str], separator: str = ",") -> list[str]:
    """A table's `lines` with a cell replaced, rows dropped or repeated, its header damaged,
    or cut off mid-line (drawn by Hypothesis)."""
    lines = list(lines)
    kind = data.draw(st.sampled_from(["cell", "drop", "repeat", "header", "cut"]),
                     label="corruption")
    row = data.draw(st.integers(1, len(lines) - 1), label="row")
    if kind == "cell":
        cells = lines[row].split(separator)
        col = data.draw(st.integers(0, len(cells) - 1), label="column")
        cells[col] = data.draw(CELLS, label="value")
        lines[row] = separator.join(cells)
    elif kind == "drop":
        del lines[row:row + data.draw(st.integers(1, 50), label="rows")]
    elif kind == "repeat":
        lines.insert(row, lines[row])
    elif kind == "header":
        lines[0] = data.draw(st.sampled_from(["", "time", lines[0].upper(), "a,b,c"]),
                             label="header")
    else:
        lines = [*lines[:row], lines[row][: len(lines[row]) // 2]]
    return lines


def assert_contract(code: int, err: str, named: str | tuple[str, ...], out) -> None:
    """Exit 0, or exit 2 with one line naming `named` (or one of several files: a log and
    the card or map that reads it), no traceback and nothing at `out`."""
    assert code in (0, 2), err
    if code == 2:
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert any(n in err for n in ((named,) if isinstance(named, str) else named)), err
        assert not out.exists()
