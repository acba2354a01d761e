"""mkdocs-gen-files script: writes the generated pages (`pages.py`) into the site."""

from __future__ import annotations

import sys
from pathlib import Path

import mkdocs_gen_files

sys.path.insert(0, str(Path(__file__).parent))
import pages

with mkdocs_gen_files.open("commands.md", "w") as fh:
    fh.write(pages.command_reference())

schemas = sorted(pages.SCHEMAS.glob("*.schema.json"))
with mkdocs_gen_files.open("formats/index.md", "w") as fh:
    fh.write(pages.format_index(schemas))
for path in schemas:
    with mkdocs_gen_files.open(f"formats/{path.stem.replace('.schema', '')}.md", "w") as fh:
        fh.write(pages.format_page(path))

for path in sorted(pages.TUTORIALS.glob("*.py")):
    with mkdocs_gen_files.open(f"tutorials/{path.stem}.md", "w") as fh:
        fh.write(pages.tutorial_page(path))
with mkdocs_gen_files.open("tutorials/discovery.md", "w") as fh:
    fh.write(pages.tutorial_page(pages.ROOT / "docs" / "notebook.py"))

with mkdocs_gen_files.open("results.md", "w") as fh:
    fh.write(pages.results_page(sorted(pages.RESULTS.glob("*.json"))))

# Validation: each `<!-- result: NAME -->` line becomes that benchmark's recorded result.
with mkdocs_gen_files.open("validation.md", "w") as fh:
    fh.write(pages.validation_page((pages.ROOT / "docs" / "validation.md").read_text()))
