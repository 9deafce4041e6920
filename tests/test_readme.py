"""Every python block of the README and of the documentation pages runs as written.

The pages are found by a glob (``docs/**/*.md``), so a page added later is covered without
touching this file. Each block runs in a fresh namespace, in a temporary working directory, on
one torch thread. A block that cannot run in a test (a long training) belongs in a ``bash``
block, whose commands ``test_readme_commands.py`` parses.
"""
import pathlib
import re

import pytest
import torch

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]


def python_blocks(text: str):
    """The ``python`` fenced blocks of a Markdown text."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


BLOCKS = [(page.relative_to(ROOT).as_posix(), i, block)
          for page in PAGES for i, block in enumerate(python_blocks(page.read_text()))]


def test_the_readme_and_the_docs_have_python_blocks():
    per_page = {}
    for page, _, _ in BLOCKS:
        per_page[page] = per_page.get(page, 0) + 1
    assert per_page.get("README.md", 0) >= 3
    assert sum(n for page, n in per_page.items() if page.startswith("docs/")) >= 8
    assert {"docs/quickstart.md", "docs/environments.md", "docs/multi_agent.md", "docs/agents.md",
            "docs/planning.md", "docs/mapf.md"} <= set(per_page)


def test_blocks_are_found_at_any_indentation_of_the_page():
    text = "intro\n\n```python\nx = 1\n```\n\n```bash\nls\n```\n\n```python\ny = 2\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = 2\n"]


@pytest.mark.parametrize("page, index, block", BLOCKS, ids=[f"{p}:{i}" for p, i, _ in BLOCKS])
def test_a_python_block_runs(page, index, block, monkeypatch, tmp_path):
    torch.set_num_threads(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(block, f"{page} block {index}", "exec"), {"__name__": f"doc_block_{index}"})


def test_the_readme_stays_a_front_door():
    """The README is short (the documentation pages hold the rest) and links into them."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    linked = set(re.findall(r"\]\((docs/[^)#]+\.md)", text))
    assert {"docs/quickstart.md", "docs/evaluation.md", "docs/benchmarks.md"} <= linked
    assert all((ROOT / page).is_file() for page in linked), linked
