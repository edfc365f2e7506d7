"""The guide's Python pages run: every ```python block of docs/src/tutorials/python.md and of the
Python API reference (docs/src/reference/python.md, which includes python/README.md), in page
order, in one fresh interpreter per page, so a block that no longer runs fails here."""

import os
import re
import subprocess
import sys

import pytest

from conftest import ROOT

PAGES = ["docs/src/tutorials/python.md", "docs/src/reference/python.md"]
INCLUDE = re.compile(r"\{\{#include\s+(\S+?)(?::(\d*))?(?::(\d*))?\s*\}\}")


def page_text(path):
    """The page as mdBook renders it: `{{#include FILE[:START[:END]]}}` replaced by those lines."""
    with open(path, encoding="utf-8") as f:
        text = f.read()

    def include(m):
        target = os.path.normpath(os.path.join(os.path.dirname(path), m.group(1)))
        with open(target, encoding="utf-8") as f:
            lines = f.read().splitlines(keepends=True)
        start = int(m.group(2)) - 1 if m.group(2) else 0
        end = int(m.group(3)) if m.group(3) else len(lines)
        return "".join(lines[start:end])

    return INCLUDE.sub(include, text)


def python_blocks(text):
    """The ```python blocks of a Markdown text, with the line each starts at."""
    blocks, current, start = [], None, 0
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if current is None and stripped.startswith("```python"):
            current, start = [], n + 1
        elif current is not None and stripped.startswith("```"):
            blocks.append((start, "\n".join(current)))
            current = None
        elif current is not None:
            current.append(line)
    assert current is None, "a ```python block is not closed"
    return blocks


RUNNER = """
import sys
blocks = {blocks!r}
namespace = {{"__name__": "__main__"}}
for name, code in blocks:
    exec(compile(code, name, "exec"), namespace)
"""


@pytest.mark.parametrize("page", PAGES)
def test_the_python_blocks_of_the_page_run(page, tmp_path):
    blocks = python_blocks(page_text(os.path.join(ROOT, page)))
    assert blocks, f"{page} has no ```python block"
    # The blocks name files as from the repository root (scenes/...) and write into out/: they
    # run in a scratch folder where scenes/ is the repository's.
    os.symlink(os.path.join(ROOT, "scenes"), tmp_path / "scenes")
    named = [(f"{page} (block at line {start})", code) for start, code in blocks]
    env = dict(os.environ, MPLBACKEND="Agg")
    r = subprocess.run(
        [sys.executable, "-c", RUNNER.format(blocks=named)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, f"a Python block of {page} failed:\n{r.stderr[-4000:]}"


def test_blocks_are_found_in_included_files_and_a_failing_block_fails(tmp_path):
    # The extraction itself: an include is expanded, and a broken block makes the runner fail.
    readme = python_blocks(page_text(os.path.join(ROOT, "docs/src/reference/python.md")))
    assert len(readme) >= 2
    named = [("ok", "x = 1"), ("broken", "assert x == 2, 'the block is wrong'")]
    r = subprocess.run([sys.executable, "-c", RUNNER.format(blocks=named)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "the block is wrong" in r.stderr and 'File "broken"' in r.stderr
