"""The package's layout shows the pipeline: a few folders named for its stages, few loose
modules, and an engine made of short functions."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).parents[1] / "cpas_ocp"
ENGINE = PACKAGE / "estimation"
LONGEST = 80  # lines a function of the engine may take


def test_the_package_is_a_few_stages_and_few_loose_modules() -> None:
    folders = sorted(p.name for p in PACKAGE.iterdir()
                     if p.is_dir() and (p / "__init__.py").is_file())
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert 5 <= len(folders) <= 8, folders
    assert len(loose) <= 8, loose


def test_no_function_of_the_engine_is_longer_than_80_lines() -> None:
    long = []
    for path in sorted(ENGINE.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > LONGEST:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, long
