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
from typing import Dict, List, Tuple

import numpy as np

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


__all__ = ["APARTMENTS", "Apartment", "Box", "GridMap", "MAPS", "get_map"]
