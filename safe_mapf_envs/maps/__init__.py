"""Maps as data.

A 2D map is an occupancy grid (``#`` blocked, ``.`` free) scaled by a resize factor ``f``:
an ``H x W`` grid becomes a continuous world of ``(H*f) x (W*f)`` units. World coordinates are
``x`` along columns and ``y`` along rows (row 0 at the top, as in an image), so grid cell
``(i, j)`` covers ``[j*f, (j+1)*f] x [i*f, (i+1)*f]``.

The layouts follow the family of maps used by Search on the Replay Buffer (SoRB); the
``CentralObstacle`` map is the 2D benchmark of the paper "Safe Multi-Agent Navigation guided
by Goal-Conditioned Safe Reinforcement Learning".
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple, Union

import numpy as np

from .files import MapFileError, blocked_grid, read_grid, read_image, read_movingai

Box = Tuple[float, float, float, float]  # (x0, y0, x1, y1) in world units


@dataclass(frozen=True)
class GridMap:
    """An occupancy-grid map and the defaults of the environments built on it.

    Attributes:
        name: map name, used in env ids (``Safe<name>-v0``).
        rows: the grid, one string per row, ``#`` blocked and ``.`` free.
        resize_factor: world units per grid cell.
        cost_radius: default radius of influence ``r`` of the cost function, in world units.
        description: one line for tables and docs.
    """

    name: str
    rows: Tuple[str, ...]
    resize_factor: float
    cost_radius: float
    description: str = ""
    _grid: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        widths = {len(r) for r in self.rows}
        if len(widths) != 1:
            raise ValueError(f"map {self.name!r}: rows have different widths {sorted(widths)}")
        bad = set("".join(self.rows)) - set("#.")
        if bad:
            raise ValueError(f"map {self.name!r}: unknown cell characters {sorted(bad)}")
        grid = np.array([[c == "#" for c in r] for r in self.rows], dtype=bool)
        object.__setattr__(self, "_grid", grid)

    @classmethod
    def from_array(
        cls,
        blocked: np.ndarray,
        name: str = "Map",
        resize_factor: float = 3.0,
        cost_radius: Optional[float] = None,
        description: str = "",
        largest_component: bool = True,
    ) -> "GridMap":
        """A map from a boolean occupancy array, ``True`` (or 1) where a cell is blocked.

        Args:
            blocked: ``(H, W)`` array; row 0 is the top of the map.
            name: map name (env ids read ``Safe<name>-v0``).
            resize_factor: world units per cell (default 3: a one-cell corridor is three agent
                diameters wide, as in the registered ``Maze`` and ``Spiral`` maps).
            cost_radius: radius of influence of the cost in world units (default: one cell,
                ``resize_factor``).
            description: one line for tables.
            largest_component: block the free cells outside the largest 4-connected free region,
                so that every start can reach every goal (MovingAI maps often hold closed pockets).

        Raises ``ValueError`` when the array is not 2D boolean / 0-1 or has no free cell.
        """
        grid = blocked_grid(blocked, what=f"map {name!r}")
        if grid.all():
            raise ValueError(f"map {name!r}: every cell is blocked; a map needs at least one free cell")
        if largest_component:
            grid = _keep_largest_region(grid)
        rows = tuple("".join("#" if b else "." for b in row) for row in grid)
        radius = float(resize_factor) if cost_radius is None else float(cost_radius)
        return cls(name, rows, resize_factor=float(resize_factor), cost_radius=radius, description=description)

    @classmethod
    def from_movingai(cls, path: Union[str, Path], resize_factor: float = 3.0,
                      cost_radius: Optional[float] = None, name: Optional[str] = None,
                      largest_component: bool = True) -> "GridMap":
        """A map from a MovingAI ``.map`` file (``.GS`` free, ``@OTW`` blocked).

        ``name`` defaults to the file's stem with its first letter capitalised
        (``room-32-32-4.map`` -> ``Room-32-32-4``); the other arguments are as for
        :meth:`from_array`. A file that breaks the format raises
        :class:`~safe_mapf_envs.maps.files.MovingAIFormatError` naming the file and line.
        """
        path = Path(path)
        return cls._from_grid(read_movingai(path), path, resize_factor, cost_radius, name, largest_component,
                              f"MovingAI map {path.name}")

    @classmethod
    def from_image(cls, path: Union[str, Path], resize_factor: float = 3.0,
                   cost_radius: Optional[float] = None, name: Optional[str] = None,
                   largest_component: bool = True, threshold: float = 128.0) -> "GridMap":
        """A map from an occupancy image: one pixel per cell, dark (grey level below
        ``threshold``) = blocked. Other arguments as for :meth:`from_movingai`; a file that is not
        an image raises :class:`~safe_mapf_envs.maps.files.MapFileError` naming it."""
        path = Path(path)
        return cls._from_grid(read_image(path, threshold), path, resize_factor, cost_radius, name,
                              largest_component, f"occupancy image {path.name}")

    @classmethod
    def from_file(cls, path: Union[str, Path], resize_factor: float = 3.0,
                  cost_radius: Optional[float] = None, name: Optional[str] = None,
                  largest_component: bool = True) -> "GridMap":
        """A map from a file of any supported format, chosen by its suffix: a MovingAI ``.map``,
        an image (``.png``, ``.bmp``, ``.jpg``, ``.pgm``, ``.tif``) or a ``.npy`` boolean array
        (``True`` = blocked). Arguments as for :meth:`from_movingai`."""
        path = Path(path)
        return cls._from_grid(read_grid(path), path, resize_factor, cost_radius, name, largest_component,
                              f"map file {path.name}")

    @classmethod
    def _from_grid(cls, blocked: np.ndarray, path: Path, resize_factor: float, cost_radius: Optional[float],
                   name: Optional[str], largest_component: bool, description: str) -> "GridMap":
        if not blocked.size or blocked.all():
            raise MapFileError(f"{path}: every cell is blocked; a map needs at least one free cell")
        return cls.from_array(blocked, name or map_name_from_path(path), resize_factor, cost_radius,
                              description=description, largest_component=largest_component)

    @property
    def grid(self) -> np.ndarray:
        """Boolean occupancy grid of shape ``(H, W)``; ``True`` means blocked."""
        return self._grid

    @property
    def shape(self) -> Tuple[int, int]:
        return self._grid.shape

    @property
    def size(self) -> Tuple[float, float]:
        """World extent ``(width, height)`` in units."""
        h, w = self._grid.shape
        return (w * self.resize_factor, h * self.resize_factor)

    def boxes(self) -> List[Box]:
        """Blocked cells merged into axis-aligned rectangles, in world units.

        Runs of blocked cells in each row are merged horizontally, then identical runs in
        consecutive rows are merged vertically. The result covers exactly the blocked cells.
        """
        grid = self._grid
        f = float(self.resize_factor)
        open_runs: Dict[Tuple[int, int], int] = {}  # (j0, j1) -> first row
        out: List[Box] = []
        h, w = grid.shape
        for i in range(h + 1):
            runs = set()
            if i < h:
                j = 0
                while j < w:
                    if grid[i, j]:
                        j0 = j
                        while j < w and grid[i, j]:
                            j += 1
                        runs.add((j0, j))
                    else:
                        j += 1
            for run in sorted(set(open_runs) - runs):
                i0 = open_runs.pop(run)
                out.append((run[0] * f, i0 * f, run[1] * f, i * f))
            for run in sorted(runs - set(open_runs)):
                open_runs[run] = i
        return sorted(out, key=lambda b: (b[1], b[0]))


def _keep_largest_region(blocked: np.ndarray) -> np.ndarray:
    """``blocked`` with every free cell outside the largest 4-connected free region blocked too."""
    from scipy import ndimage

    labels, n = ndimage.label(~blocked)
    if n <= 1:
        return blocked
    sizes = np.bincount(labels.ravel())[1:]
    return labels != (1 + int(np.argmax(sizes)))


def map_name_from_path(path: Union[str, Path]) -> str:
    """A map name from a file name: its stem with the first letter capitalised and every character
    an env id cannot hold (anything but letters, digits, ``_``, ``.`` and ``-``) replaced by ``_``."""
    stem = Path(path).stem
    cleaned = "".join(ch if ch.isalnum() or ch in "_.-" else "_" for ch in stem) or "Map"
    return cleaned[0].upper() + cleaned[1:]


def _rows(text: str) -> Tuple[str, ...]:
    return tuple(line.strip() for line in text.strip().splitlines())


MAPS: Dict[str, GridMap] = {}


def _add(m: GridMap) -> None:
    MAPS[m.name] = m


_add(GridMap(
    "CentralObstacle",
    _rows("""
        ...........
        ...........
        ...........
        ...........
        ....###....
        ....###....
        ....###....
        ...........
        ...........
        ...........
        ...........
    """),
    resize_factor=5,
    cost_radius=10.0,
    description="55x55 open room with a 15x15 block in the middle (the paper's 2D benchmark)",
))
_add(GridMap(
    "CenterDot",
    _rows("""
        .....
        .....
        ..#..
        .....
        .....
    """),
    resize_factor=3,
    cost_radius=3.0,
    description="15x15 room with one small block in the centre",
))
_add(GridMap(
    "FourRooms",
    _rows("""
        .....#.....
        .....#.....
        ...........
        .....#.....
        .....#.....
        ##.####....
        .....###.##
        .....#.....
        .....#.....
        ...........
        .....#.....
    """),
    resize_factor=5,
    cost_radius=5.0,
    description="four rooms joined by one-cell doors",
))
_add(GridMap(
    "Spiral",
    _rows("""
        .........
        .#######.
        .#.....#.
        .#.###.#.
        .#.#...#.
        .#.#####.
        .#.......
        .########
        .........
    """),
    resize_factor=3,
    cost_radius=3.0,
    description="a corridor winding inwards to the centre",
))
_add(GridMap(
    "Maze",
    _rows("""
        .....#.....
        .###.#.###.
        .#...#...#.
        .#.#####.#.
        .#.....#.#.
        .#####.#.#.
        ...#...#...
        ##.#.#####.
        ...#.....#.
        .#######.#.
        .........#.
    """),
    resize_factor=3,
    cost_radius=3.0,
    description="an 11x11 maze of one-cell corridors",
))
_add(GridMap(
    "U",
    _rows("""
        .....
        .#.#.
        .#.#.
        .###.
        .....
    """),
    resize_factor=5,
    cost_radius=5.0,
    description="a U-shaped wall whose inside is a dead end",
))
_add(GridMap(
    "Tunnel",
    _rows("""
        .........
        .........
        ###.#####
        ###.#####
        ###.#####
        ###.#####
        ###.#####
        .........
        .........
    """),
    resize_factor=3,
    cost_radius=3.0,
    description="two halls joined by a long one-cell tunnel",
))


from .apartments import APARTMENTS, Apartment  # noqa: E402  (furnished layouts in metres)


def get_map(name: str):
    """Return the 2D map (:data:`MAPS`) or furnished apartment (:data:`APARTMENTS`) called ``name``.

    Raises ``KeyError`` listing the known names otherwise.
    """
    if name in MAPS:
        return MAPS[name]
    if name in APARTMENTS:
        return APARTMENTS[name]
    known = ", ".join(sorted(MAPS) + sorted(APARTMENTS))
    raise KeyError(f"unknown map {name!r}; known maps: {known}")


__all__ = ["APARTMENTS", "Apartment", "Box", "GridMap", "MAPS", "MapFileError", "get_map", "map_name_from_path"]
