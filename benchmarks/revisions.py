"""Run benchmark code against the cpas_ocp of another git revision, in a child process.

Speed-ups are measured as ratios against the code they replace, run by the
same script on the same machine.  `code_at` checks a revision out in a
temporary worktree; `run_child` runs a script in a fresh Python process whose
``import cpas_ocp`` resolves to a given code tree (this tree's or a
worktree's), and returns the JSON object the script prints last.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Prepended to every child script: the project is installed in development mode,
# so its import mapping is pointed at the code tree given as the first argument.
PRELUDE = r"""
import sys
from pathlib import Path
code = Path(sys.argv[1])
for module in list(sys.modules.values()):
    if type(getattr(module, "MAPPING", None)) is dict and "cpas_ocp" in module.MAPPING:
        module.MAPPING.update({"cpas_ocp": str(code / "cpas_ocp"),
                               "cpas_ocp.problem_data": str(code / "problems"),
                               "cpas_ocp.schemas": str(code / "data_schemas")})
        module.NAMESPACES.update({"cpas_ocp": [str(code / "cpas_ocp")]})
sys.argv = sys.argv[1:]
"""


@contextlib.contextmanager
def code_at(revision: str | None) -> Iterator[Path]:
    """This tree (`revision` None) or a temporary worktree of `revision`."""
    if revision is None:
        yield ROOT
        return
    with tempfile.TemporaryDirectory() as tmp:
        worktree = Path(tmp) / "code"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(worktree),
                        revision], check=True, capture_output=True)
        try:
            yield worktree
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(worktree)], check=False, capture_output=True)


def run_child(script: str, code: Path, *args: str, cache: Path | None = None) -> dict:
    """Run `script` in a fresh process importing cpas_ocp from `code`; its last printed
    line, parsed as JSON.  `cache` is its compile cache (a new empty one when None)."""
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "CPAS_OCP_CACHE": str(cache or scratch)}
        out = subprocess.run([sys.executable, "-c", PRELUDE + script, str(code), *args],
                             env=env, cwd=scratch, capture_output=True, text=True, check=False)
    if out.returncode:
        raise RuntimeError(f"{' '.join(args)} with the code in {code} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])
