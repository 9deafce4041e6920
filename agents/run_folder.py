"""Output folders that a run owns: nothing overwritten by accident, resumed only with the same settings.

A command that writes into a folder (``safe-mapf train``, ``train-marl``, ``evaluate``) records its
settings there in a JSON file (the *record*). :class:`RunFolder` decides, before any work, what a
new run may do with the folder:

* an empty or new folder: the run starts;
* a folder that holds files, without ``resume`` or ``overwrite``: refused, naming the files;
* ``overwrite``: the files an earlier run of that command wrote (and only those) are removed first;
* ``resume``: the recorded settings are compared with the new ones, and any difference in a setting
  that matters is refused, naming it.

:func:`read_json`, :func:`read_json_lines` and :func:`read_npz` read a run's files with errors that
name the file. :func:`write_atomic` writes a file whole or not at all (a temporary file in the same folder, then
a rename), so that a run killed at any moment leaves either the old file or the new one.
"""
from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import shutil
import zipfile
import zlib
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]


class OutputFolderError(ValueError):
    """A run may not use its output folder as asked (it holds an earlier run, or other settings)."""


def write_atomic(path: PathLike, data: Union[str, bytes]) -> None:
    """Write ``data`` to ``path`` whole or not at all: a temporary file beside it, then a rename."""
    with atomic_output(path) as tmp:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data)


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix) for a writer that takes a path (a figure, an
    animation); renamed to ``path`` when the block ends without an error, removed otherwise."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_json_atomic(path: PathLike, obj: Any, indent: Optional[int] = 2) -> None:
    """:func:`write_atomic` of ``obj`` as JSON."""
    write_atomic(path, json.dumps(obj, indent=indent) + "\n")


def read_json(path: PathLike, what: str = "file") -> Any:
    """The JSON content of ``path``; a ``ValueError`` naming the file if it is not JSON."""
    try:
        with open(path) as f:
            return json.load(f)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{what} {str(path)!r} is not valid JSON ({exc.msg} at line {exc.lineno}); "
                         "it may have been cut off") from None
    except UnicodeDecodeError:
        raise ValueError(f"{what} {str(path)!r} is not a text file") from None


def read_npz(path: PathLike, what: str) -> Dict[str, np.ndarray]:
    """Every array of the ``.npz`` file at ``path``, read whole (each member checked against its
    checksum) without pickle; a missing, truncated or corrupt file raises ``ValueError`` naming
    ``path`` (``what`` says what the file should be)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in z.files}
    except FileNotFoundError as exc:
        raise ValueError(f"no {what} at {path}") from exc
    except (OSError, KeyError, EOFError, ValueError, zipfile.BadZipFile, zlib.error, NotImplementedError) as exc:
        raise ValueError(f"cannot read {path}: it is not a {what} (not an .npz file, or truncated or corrupt: "
                         f"{type(exc).__name__}: {exc})") from exc


def read_json_lines(path: PathLike) -> List[Dict[str, Any]]:
    """The records of a JSON-lines log; a last line cut off by an interruption is dropped, any
    other unreadable line is an error naming the file and the line."""
    records: List[Dict[str, Any]] = []
    with open(path) as f:
        lines = f.read().split("\n")
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            if i >= len(lines) - 2 and not any(x.strip() for x in lines[i + 1:]):  # the last line: cut off
                break
            raise ValueError(f"{str(path)!r} line {i + 1} is not valid JSON") from None
    return records


def _hidden(name: str) -> bool:
    return name.startswith(".")


class RunFolder:
    """The output folder of one command.

    Args:
        path: the folder.
        command: the command's name, used in messages (e.g. ``"safe-mapf train"``).
        owned: glob patterns (relative to the folder) of what the command writes; ``--overwrite``
            removes what matches them, files or folders, and nothing else.
        record: the file (one of ``owned``) in which the settings are recorded.
        flag: the option that names the folder, for messages.
        settings_key: the record's entry that holds the settings.
    """

    def __init__(self, path: PathLike, command: str, owned: Sequence[str], record: str,
                 flag: str = "--out", settings_key: str = "settings") -> None:
        self.path = Path(path)
        self.command = command
        self.owned = tuple(owned)
        self.record = record
        self.flag = flag
        self.settings_key = settings_key

    @property
    def record_path(self) -> Path:
        return self.path / self.record

    def contents(self) -> List[str]:
        """The names in the folder (hidden ones aside), sorted; empty if it does not exist."""
        if not self.path.is_dir():
            return []
        return sorted(n for n in os.listdir(self.path) if not _hidden(n))

    def owned_names(self) -> List[str]:
        """The names in the folder that match :attr:`owned`."""
        return [n for n in self.contents() if any(fnmatch.fnmatch(n, p) for p in self.owned)]

    def recorded(self) -> Optional[Dict[str, Any]]:
        """The recorded settings, or ``None`` when there is no record."""
        if not self.record_path.is_file():
            return None
        data = read_json(self.record_path, what="the run's record")
        if not isinstance(data, dict):
            raise ValueError(f"the run's record {str(self.record_path)!r} is not a JSON object")
        return data

    def check(self, settings: Dict[str, Any], resume: bool = False, overwrite: bool = False,
              may_differ: Iterable[str] = (), describe: Optional[Callable[[str], str]] = None) -> None:
        """Raise :class:`OutputFolderError` unless a run with ``settings`` may use the folder as asked.

        ``may_differ``: settings a resumed run may change (e.g. the number of steps in all);
        every other recorded setting must be equal. ``describe(key)`` names a setting in messages
        (default: the key). Nothing is written.
        """
        if resume and overwrite:
            raise OutputFolderError("give --resume (continue the run) or --overwrite (start it anew), not both")
        if self.path.exists() and not self.path.is_dir():
            raise OutputFolderError(f"{self.flag} {str(self.path)!r} is a file, not a folder")
        names = self.contents()
        if resume:
            recorded = self.recorded()
            if recorded is None:
                raise OutputFolderError(f"nothing to resume in {self.flag} {str(self.path)!r}: it has no "
                                        f"{self.record} of an earlier {self.command} run")
            diffs = differences(recorded.get(self.settings_key, {}), settings, may_differ)
            if diffs:
                name = describe or (lambda k: k)
                raise OutputFolderError(
                    f"{self.flag} {str(self.path)!r} holds a {self.command} run with other settings; --resume "
                    "continues a run only with its own: " + "; ".join(
                        f"{name(k)}: {_show(a)} there, {_show(b)} now" for k, a, b in diffs))
            return
        if names and not overwrite:
            shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
            raise OutputFolderError(
                f"{self.flag} {str(self.path)!r} is not empty ({shown}): give --resume to continue the run in it, "
                f"--overwrite to replace what an earlier {self.command} run wrote there, or another {self.flag}")

    def prepare(self, settings: Dict[str, Any], resume: bool = False, overwrite: bool = False,
                may_differ: Iterable[str] = (), describe: Optional[Callable[[str], str]] = None,
                extra: Optional[Dict[str, Any]] = None) -> Optional[Dict[str, Any]]:
        """:meth:`check`, then make the folder ready: with ``overwrite``, remove what an earlier run
        wrote; create the folder; write the record (``settings`` and ``extra``, e.g. the command
        line) for a new run, or add ``extra`` to the record's ``resumed`` list for a resumed one.
        Returns the earlier record when resuming, else ``None``."""
        self.check(settings, resume=resume, overwrite=overwrite, may_differ=may_differ, describe=describe)
        if overwrite:
            for name in self.owned_names():
                target = self.path / name
                if target.is_dir() and not target.is_symlink():
                    shutil.rmtree(target)
                else:
                    target.unlink()
        self.path.mkdir(parents=True, exist_ok=True)
        if resume:
            recorded = self.recorded() or {}
            recorded.setdefault("resumed", []).append({**(extra or {}), self.settings_key: settings})
            write_json_atomic(self.record_path, recorded)
            return recorded
        write_json_atomic(self.record_path, {self.settings_key: settings, **(extra or {})})
        return None


def differences(recorded: Dict[str, Any], settings: Dict[str, Any],
                may_differ: Iterable[str] = ()) -> List[tuple]:
    """``(key, recorded value, new value)`` for each setting both name that differs (JSON-normalised),
    the keys in ``may_differ`` aside."""
    skip = set(may_differ)
    norm = json.loads(json.dumps(settings))
    keys = sorted((set(recorded) & set(norm)) - skip)
    return [(k, recorded.get(k), norm.get(k)) for k in keys if recorded.get(k) != norm.get(k)]


def _show(value: Any) -> str:
    return "unset" if value is None else json.dumps(value)


__all__ = ["OutputFolderError", "RunFolder", "atomic_output", "differences", "read_json", "read_json_lines", "read_npz",
           "write_atomic", "write_json_atomic"]
