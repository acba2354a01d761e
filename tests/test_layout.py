"""The package's layout shows the pipeline: a few folders named for its stages, few loose
modules, and an engine made of short functions."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

PACKAGE = Path(__file__).parents[1] / "cpas_ocp"
ENGINE = PACKAGE / "estimation"
LONGEST = 80  # lines a function of the engine may take


def _layers() -> list[list[str]]:
    """The import contract's layers (pyproject.toml), highest first, as module names."""
    project = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
    contract = project["tool"]["importlinter"]["contracts"][0]
    return [[m.strip().removeprefix("cpas_ocp.") for m in layer.split("|")]
            for layer in contract["layers"]]


def test_the_package_is_its_pipeline_s_stages_and_few_loose_modules() -> None:
    """Every folder is a stage of the pipeline, a layer of the import contract, and the
    loose modules are the bottom layer's few (errors, signals, progress)."""
    folders = sorted(p.name for p in PACKAGE.iterdir()
                     if p.is_dir() and (p / "__init__.py").is_file())
    loose = sorted(p.stem for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    layers = _layers()
    assert folders == sorted(m for layer in layers[:-1] for m in layer), folders
    assert set(loose) <= set(layers[-1]) and len(loose) <= 6, loose


def test_no_function_of_the_engine_is_longer_than_80_lines() -> None:
    long = []
    for path in sorted(ENGINE.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > LONGEST:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, long


def test_every_subpackage_is_installed() -> None:
    """A wheel carries the packages pyproject.toml lists: every folder of the package with
    an __init__.py must be among them."""
    listed = set(tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
                 ["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(PACKAGE.parent).parts)
             for p in PACKAGE.rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)
