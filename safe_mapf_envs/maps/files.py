"""Occupancy grids read from files: MovingAI ``.map`` files, images and NumPy arrays.

Every reader returns a boolean grid of shape ``(H, W)``, ``True`` where a cell is blocked, row 0
at the top (as :class:`~safe_mapf_envs.maps.GridMap` stores it), and refuses a file that does not
follow its format with a :class:`MapFileError` whose message names the file and, where one is to
blame, the line (``path:line: ...``) or the pixel. Files are read as data: ``.npy`` arrays are
loaded without pickle, so loading a map never runs code from it.

Formats:

- MovingAI ``.map`` (the grid maps of the MovingAI MAPF benchmark, Stern et al., "Multi-Agent
  Pathfinding: Definitions, Variants, and Benchmarks"): a header (``type``, ``height H``,
  ``width W``) ending with a line ``map``, then ``H`` rows of ``W`` characters; ``.``, ``G`` and
  ``S`` are free, ``@``, ``O``, ``T`` and ``W`` blocked.
- images (``.png``, ``.bmp``, ``.jpg``, ``.jpeg``, ``.pgm``, ``.tif``, ``.tiff``): one pixel per
  cell; a pixel darker than the threshold (on a 0-255 grey scale) is blocked.
- ``.npy``: a 2D boolean (or 0/1 integer) array, ``True`` / 1 = blocked.
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Union

import numpy as np

PathLike = Union[str, Path]

#: characters of a MovingAI ``.map`` grid an agent may stand on
FREE_CHARS = frozenset(".GS")
#: characters of a MovingAI ``.map`` grid an agent may not enter (out of bounds, trees, water)
BLOCKED_CHARS = frozenset("@OTW")
#: file suffixes read as images
IMAGE_SUFFIXES = (".png", ".bmp", ".jpg", ".jpeg", ".pgm", ".tif", ".tiff")
#: every suffix :func:`read_grid` accepts
MAP_SUFFIXES = (".map", ".npy") + IMAGE_SUFFIXES


class MapFileError(ValueError):
    """A map file that cannot be read as one; the message names the file and, where one is to
    blame, the line or pixel."""


class MovingAIFormatError(MapFileError):
    """A ``.map`` or ``.scen`` file that does not follow the MovingAI format; the message names
    the file and, where one is to blame, the line (``path:line: ...``)."""


def read_text_lines(path: PathLike, error: type = MapFileError) -> List[str]:
    """The lines of a text file; ``error`` naming the file when it is missing or not UTF-8 text."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except IsADirectoryError:
        raise error(f"{path}: a folder, not a file") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file (the byte at offset {exc.start} is not UTF-8)") from None
    if "\0" in text:
        raise error(f"{path}: not a text file (it holds NUL bytes)")
    return text.splitlines()


def read_movingai(path: PathLike) -> np.ndarray:
    """The blocked cells of a MovingAI ``.map`` file.

    The header (``type``, ``height``, ``width``) ends with a line ``map``; then come exactly
    ``height`` rows of ``width`` characters from ``.GS`` (free) and ``@OTW`` (blocked). Trailing
    whitespace of a row and blank lines after the grid are ignored; anything else that breaks
    these rules raises :class:`MovingAIFormatError` naming the file and line.
    """
    path = Path(path)
    lines = read_text_lines(path, MovingAIFormatError)
    header = {}
    i = 0
    while i < len(lines) and lines[i].strip().lower() != "map":
        parts = lines[i].split()
        if len(parts) == 2:
            header[parts[0].lower()] = parts[1]
        i += 1
    if i == len(lines):
        raise MovingAIFormatError(f"{path}: no 'map' line in the header")
    try:
        h, w = int(header["height"]), int(header["width"])
    except (KeyError, ValueError):
        raise MovingAIFormatError(f"{path}: header needs integer 'height' and 'width'") from None
    if h < 1 or w < 1:
        raise MovingAIFormatError(f"{path}: the header gives a {h} x {w} map (height x width); "
                                  "both must be at least 1")
    first = i + 1  # index of the grid's first row in ``lines``
    rows = [r.rstrip() for r in lines[first:first + h]]
    if len(rows) < h:
        raise MovingAIFormatError(f"{path}: the header gives height {h}, the grid has {len(rows)} rows")
    extra = next((j for j in range(first + h, len(lines)) if lines[j].strip()), None)
    if extra is not None:
        raise MovingAIFormatError(f"{path}:{extra + 1}: the header gives height {h}, the grid goes on past it")
    known = FREE_CHARS | BLOCKED_CHARS
    for j, r in enumerate(rows):
        ln = first + j + 1
        if len(r) != w:
            raise MovingAIFormatError(f"{path}:{ln}: row of {len(r)} characters, the header gives width {w}")
        bad = next((ch for ch in r if ch not in known), None)
        if bad is not None:
            raise MovingAIFormatError(f"{path}:{ln}: unknown map character {bad!r} in column {r.index(bad) + 1} "
                                      f"(free: {''.join(sorted(FREE_CHARS))}; "
                                      f"blocked: {''.join(sorted(BLOCKED_CHARS))})")
    return np.array([[ch not in FREE_CHARS for ch in r] for r in rows], dtype=bool)


def read_image(path: PathLike, threshold: float = 128.0) -> np.ndarray:
    """The blocked cells of an occupancy image: one pixel per cell, a pixel darker than
    ``threshold`` (grey level 0-255; colour images are converted to grey first) is blocked.

    Raises :class:`MapFileError` naming the file when it is missing or is not an image OpenCV
    can decode.
    """
    import cv2

    path = Path(path)
    if not 0.0 < float(threshold) <= 255.0:
        raise ValueError(f"threshold must be in (0, 255], got {threshold!r}")
    try:
        data = np.frombuffer(path.read_bytes(), dtype=np.uint8)
    except FileNotFoundError:
        raise MapFileError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise MapFileError(f"{path}: a folder, not a file") from None
    img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if img is None:
        raise MapFileError(f"{path}: not an image that can be read (PNG, BMP, JPEG, PGM or TIFF expected)")
    return np.asarray(img) < float(threshold)


def read_array(path: PathLike) -> np.ndarray:
    """The blocked cells of a ``.npy`` file holding a 2D boolean (or 0/1) array, ``True`` = blocked.

    The file is loaded without pickle (an object array is refused, never run); other shapes and
    values raise :class:`MapFileError` naming the file.
    """
    path = Path(path)
    try:
        arr = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise MapFileError(f"{path}: no such file") from None
    except (ValueError, OSError, EOFError) as exc:
        raise MapFileError(f"{path}: not a NumPy .npy array that can be read without pickle ({exc})") from None
    try:
        return blocked_grid(arr, what=str(path))
    except ValueError as exc:
        raise MapFileError(str(exc)) from None


def blocked_grid(array: np.ndarray, what: str = "the array") -> np.ndarray:
    """``array`` as a boolean ``(H, W)`` grid, ``True`` = blocked; ``ValueError`` naming ``what``
    unless it is 2D, non-empty and boolean or 0/1."""
    arr = np.asarray(array)
    if arr.ndim != 2 or 0 in arr.shape:
        raise ValueError(f"{what}: an occupancy grid must be a non-empty 2D array, got shape {arr.shape}")
    if arr.dtype == bool:
        return arr.copy()
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{what}: an occupancy grid must be boolean or 0/1, got dtype {arr.dtype}")
    bad = ~np.isin(arr, (0, 1))
    if bad.any():
        r, c = (int(x) for x in np.argwhere(bad)[0])
        raise ValueError(f"{what}: an occupancy grid must be boolean or 0/1; row {r}, column {c} holds "
                         f"{arr[r, c].item()!r}")
    return arr.astype(bool)


def read_grid(path: PathLike, threshold: float = 128.0) -> np.ndarray:
    """The blocked cells of a map file of any supported format, chosen by its suffix
    (:data:`MAP_SUFFIXES`); :class:`MapFileError` for another suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".map":
        return read_movingai(path)
    if suffix == ".npy":
        return read_array(path)
    if suffix in IMAGE_SUFFIXES:
        return read_image(path, threshold)
    raise MapFileError(f"{path}: unknown map format {suffix or '(no suffix)'!r}; "
                       f"expected one of {', '.join(MAP_SUFFIXES)}")


__all__ = ["BLOCKED_CHARS", "FREE_CHARS", "IMAGE_SUFFIXES", "MAP_SUFFIXES", "MapFileError", "MovingAIFormatError",
           "blocked_grid", "read_array", "read_grid", "read_image", "read_movingai", "read_text_lines"]
