"""MkDocs hook: the figures under ``examples/figures/`` (written by the figure scripts, also shown
by the README) are served under ``figures/`` without a second copy in ``docs/``."""
from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

FIGURES = Path(__file__).resolve().parents[1] / "examples" / "figures"


def on_files(files: Files, config) -> Files:
    for path in sorted(FIGURES.rglob("*")):
        if path.suffix.lower() in (".png", ".gif", ".jpg", ".svg"):
            uri = "figures/" + path.relative_to(FIGURES).as_posix()
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files

