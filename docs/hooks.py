"""MkDocs hooks.

- The figures under ``examples/figures/`` (written by the figure scripts, also shown by the
  README) are served under ``figures/`` without a second copy in ``docs/``.
- The docstrings' Sphinx roles (``:class:`~agents.search.SearchPolicy```, ``:meth:``, ``:func:``,
  ...), which the API reference would show as literal text, become links to the objects the
  reference documents (code text where it documents none).
"""
from __future__ import annotations

import html
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

FIGURES = Path(__file__).resolve().parents[1] / "examples" / "figures"


def on_files(files: Files, config) -> Files:
    for path in sorted(FIGURES.rglob("*")):
        if path.suffix.lower() in (".png", ".gif", ".jpg", ".svg"):
            uri = "figures/" + path.relative_to(FIGURES).as_posix()
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


#: a Sphinx role as Markdown renders it: the role's name, then the target as inline code
ROLE = re.compile(r":(?:py:)?(class|meth|func|mod|data|attr|exc|obj|const|paramref):<code>(~?)([\w.]+)(\(\))?</code>")


def _reference(match: re.Match) -> str:
    kind, short, target = match.group(1), match.group(2), match.group(3)
    title = target.rsplit(".", 1)[-1] if short else target
    if kind in ("meth", "func"):
        title += "()"
    # resolved by mkdocs-autorefs once every page is rendered; a target it does not know stays code text
    return f'<autoref identifier="{html.escape(target)}" optional><code>{html.escape(title)}</code></autoref>'


def on_page_content(html_text: str, page, config, files) -> str:
    return ROLE.sub(_reference, html_text)
