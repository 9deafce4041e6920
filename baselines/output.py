"""Output folders and row files of the commands: checked before any work, written as rows come.

:func:`check_output_dir` makes sure a command can write its results before it spends minutes
computing them (and removes what the check created if it cannot); :class:`RowWriter` appends
each row to a CSV file as soon as it exists, so an interrupted or failing run keeps every row
computed so far.
"""
from __future__ import annotations

import argparse
import csv
import os
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union


def check_output_dir(path: Union[str, os.PathLike], flag: str = "--out") -> Path:
    """Create ``path`` if needed and check that files can be written in it.

    Raises ``ValueError`` naming ``flag``, the folder and the reason when it cannot be created
    or written; folders the check created are removed again in that case.
    """
    out = Path(path)
    created: List[Path] = []
    try:
        if out.exists() and not out.is_dir():
            raise ValueError(f"{flag} {str(out)!r} is a file, not a folder")
        missing = [p for p in (out, *out.parents) if not p.exists()]
        for p in reversed(missing):
            p.mkdir()
            created.append(p)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".write-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        for p in reversed(created):
            try:
                p.rmdir()
            except OSError:
                pass
        raise ValueError(f"{flag} {str(out)!r} is not a writable folder: {exc.strerror or exc}") from None
    return out


def add_resume_arguments(parser: Any, resume_help: str) -> None:
    """``--resume`` (with ``resume_help``) and ``--overwrite`` for a command that owns its ``--out``
    (:class:`agents.run_folder.RunFolder`)."""
    parser.add_argument("--resume", action="store_true", help=resume_help)
    parser.add_argument("--overwrite", action="store_true",
                        help="start anew in an --out that holds an earlier run: the files that run wrote are removed "
                             "first (without --resume or --overwrite, an --out that holds files is refused)")


#: Where the figure scripts write unless asked to refresh the README's pictures.
FIGURES_OUT = Path("figures_out")


def add_figure_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out`` (default ``figures_out/``) and ``--refresh-readme`` for a script that draws figures.

    Figures go to ``--out`` so that a run never changes tracked files by accident;
    ``--refresh-readme`` writes them where the README shows them instead.
    """
    parser.add_argument("--out", type=Path, default=FIGURES_OUT, help="folder to write the figures in "
                        f"(default: {FIGURES_OUT}/)")
    parser.add_argument("--refresh-readme", action="store_true",
                        help="write into examples/figures/, the README's pictures (tracked files), instead of --out")


def figure_output_dir(args: argparse.Namespace, readme_dir: Path) -> Path:
    """The folder of :func:`add_figure_output_arguments`' choice, created and checked writable."""
    return check_output_dir(readme_dir if args.refresh_readme else args.out,
                            flag="--refresh-readme" if args.refresh_readme else "--out")


#: the per-run fields of ``runs.csv`` read as numbers
NUMERIC_FIELDS = ("agents", "problem", "cost_max", "cost_mean", "collisions", "safety_rate", "steps", "planning_time",
                  "reached", "isr", "soc", "makespan", "c_max")


def read_rows(path: Union[str, os.PathLike]) -> List[Dict[str, Any]]:
    """The rows of a ``runs.csv`` of ``safe-mapf evaluate``, with numbers (integers as written)
    and ``success`` parsed; empty fields stay empty strings."""
    with open(path, newline="") as f:
        return [parse_row(r) for r in csv.DictReader(f)]


def read_kept_rows(path: Union[str, os.PathLike]) -> List[Dict[str, str]]:
    """The complete rows of a CSV file that rows were appended to as they came (:class:`RowWriter`),
    as written (strings): a last line cut off by an interruption (no line end, or fewer fields than
    the header) is left out. A missing or empty file has none."""
    path = Path(path)
    if not path.exists():
        return []
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{str(path)!r} is not a text file") from None
    if not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    rows = list(csv.DictReader(text.splitlines(keepends=True)))
    return [r for r in rows if None not in r.values() and None not in r]


def write_rows_atomic(rows: Sequence[Dict[str, Any]], path: Union[str, os.PathLike],
                      fields: Optional[Sequence[str]] = None) -> None:
    """Write ``rows`` as CSV with a header, whole or not at all (nothing, not even a header, for no
    rows unless ``fields`` are given)."""
    import io

    from agents.run_folder import write_atomic

    rows = list(rows)
    names = list(fields) if fields is not None else (list(rows[0]) if rows else [])
    buf = io.StringIO(newline="")
    if names:
        w = csv.DictWriter(buf, fieldnames=names, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    write_atomic(path, buf.getvalue())


class RowWriter:
    """Append rows (dicts) to a CSV file as they come; the header is the first row's keys.

    The file is started anew on the first row (``append``: rows go after those already in the
    file, which keeps its header) and flushed after every row.
    """

    def __init__(self, path: Union[str, os.PathLike], fields: Optional[Sequence[str]] = None,
                 append: bool = False) -> None:
        self.path = Path(path)
        self.fields = list(fields) if fields is not None else None
        self.append = append
        self._file: Any = None
        self._writer: Optional[csv.DictWriter] = None
        self.count = 0

    def write(self, row: Dict[str, Any]) -> None:
        """Write one row (the file is created with the header on the first)."""
        if self._writer is None:
            header = None
            if self.append and self.path.exists() and self.path.stat().st_size:
                with open(self.path, newline="") as f:
                    header = next(csv.reader(f), None)
            self.fields = header or self.fields or list(row)
            self._file = open(self.path, "a" if header else "w", newline="")
            self._writer = csv.DictWriter(self._file, fieldnames=self.fields, extrasaction="ignore")
            if not header:
                self._writer.writeheader()
        self._writer.writerow(row)
        self._file.flush()
        self.count += 1

    def close(self) -> None:
        """Close the file (nothing is written if no row came)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> "RowWriter":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def parse_row(r: Dict[str, Any]) -> Dict[str, Any]:
    """A row of ``runs.csv`` as read (strings) with numbers (integers as written) and ``success``
    parsed; empty fields stay empty strings."""
    r = dict(r)
    for k in NUMERIC_FIELDS:
        v = r.get(k)
        if isinstance(v, str) and v != "":
            r[k] = int(v) if v.lstrip("-").isdigit() else float(v)
    if isinstance(r.get("success"), str):
        r["success"] = r["success"] in ("True", "true", "1")
    return r


def parse_named_values(text: Any, known: Sequence[str], cast: Any, field: str) -> Dict[str, Any]:
    """A row field of ``name=value`` parts joined by ``;`` (empty: none) as a dict, each value
    ``cast``; a name not in ``known`` is refused, naming the field."""
    if not isinstance(text, str) or not text:
        return {}
    out = {}
    for part in text.split(";"):
        name, _, value = part.partition("=")
        if name not in known:
            raise ValueError(f"unknown name {name!r} in {field} {text!r}; known: {list(known)}")
        out[name] = cast(value)
    return out


def in_cell_order(cells: Dict[tuple, Any]) -> List[Any]:
    """The values of ``cells`` keyed by ``(method, agents, difficulty)``, by method, then difficulty
    (easy, medium, hard), then agent count."""
    order = {d: i for i, d in enumerate(("easy", "medium", "hard"))}
    return [cells[k] for k in sorted(cells, key=lambda k: (k[0], order.get(k[2], 9), k[1]))]


__all__ = ["FIGURES_OUT", "NUMERIC_FIELDS", "RowWriter", "add_figure_output_arguments", "check_output_dir",
           "figure_output_dir", "in_cell_order", "parse_named_values", "parse_row", "read_kept_rows", "read_rows",
           "write_rows_atomic"]
