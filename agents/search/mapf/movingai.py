"""MovingAI MAPF benchmark grids: ``.map`` / ``.scen`` loading and conversion to a CBS graph.

Semantics of the benchmark (Stern et al., "Multi-Agent Pathfinding: Definitions, Variants,
and Benchmarks"): 4-connected moves plus wait, one step each; vertex and swap conflicts;
agents stay at their goal; the cost is the sum of final arrival times. In ``.scen`` files,
``x`` is the column and ``y`` the row; the 9th column is an 8-connected (octile) length and
is *not* the 4-connected cost, so it is loaded only for reference.

Free cells (``.``, ``G``, ``S``) become graph nodes numbered in row-major order; ``@``, ``O``,
``T`` and ``W`` are blocked. Any other character in the grid, a row of another length than the
header's ``width``, a grid of another number of rows than its ``height``, an empty grid, a file
that is not UTF-8 text or a ``.scen`` line that cannot be read is refused with a
:class:`MovingAIFormatError` that names the file (and the line).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np
from scipy import sparse

from safe_mapf_envs.maps.files import BLOCKED_CHARS, FREE_CHARS, MovingAIFormatError, read_movingai, read_text_lines

Cell = Tuple[int, int]
PathLike = Union[str, Path]


@dataclass
class GridMap:
    """An occupancy grid: ``free[row, col]`` is True where an agent may stand."""

    free: np.ndarray
    name: str = ""

    @property
    def height(self) -> int:
        return int(self.free.shape[0])

    @property
    def width(self) -> int:
        return int(self.free.shape[1])


@dataclass(frozen=True)
class ScenAgent:
    """One line of a ``.scen`` file, as (row, col) cells."""

    start: Cell
    goal: Cell
    octile_length: float
    bucket: int = 0
    #: the map the line names (file name as written) and its ``(width, height)``
    map_name: str = ""
    map_size: Tuple[int, int] = (0, 0)
    #: the line of the ``.scen`` file it was read from (1-based; 0 when not read from a file)
    line: int = field(default=0, compare=False)


def load_map(path: PathLike) -> GridMap:
    """Read a MovingAI ``.map`` file (:func:`safe_mapf_envs.maps.files.read_movingai`: anything
    that breaks the format raises :class:`MovingAIFormatError` naming the file and line)."""
    path = Path(path)
    return GridMap(~read_movingai(path), path.stem)


def load_scen(path: PathLike, k: Optional[int] = None) -> List[ScenAgent]:
    """Read the first ``k`` agents (all if ``None``) of a MovingAI ``.scen`` file.

    After an optional ``version`` line, each line has 9 columns (tab-separated, or
    whitespace-separated where it has no tab): bucket, map file, map width, map height, start x,
    start y, goal x, goal y, octile length. A line that cannot be read raises
    :class:`MovingAIFormatError` naming the file and line.
    """
    path = Path(path)
    out: List[ScenAgent] = []
    for ln, line in enumerate(read_text_lines(path, MovingAIFormatError)):
        if not line.strip() or line.lower().startswith("version"):
            continue
        parts = line.split("\t") if "\t" in line else line.split()
        if len(parts) < 9:
            raise MovingAIFormatError(f"{path}:{ln + 1}: expected 9 columns, got {len(parts)}")
        try:
            sx, sy, gx, gy = (int(p) for p in parts[4:8])
            agent = ScenAgent((sy, sx), (gy, gx), float(parts[8]), int(parts[0]), parts[1].strip(),
                              (int(parts[2]), int(parts[3])), line=ln + 1)
        except ValueError as exc:
            raise MovingAIFormatError(f"{path}:{ln + 1}: cannot read the agent's bucket, cells or length "
                                      f"({exc})") from None
        if min(sx, sy, gx, gy) < 0:
            raise MovingAIFormatError(f"{path}:{ln + 1}: negative cell coordinate")
        out.append(agent)
        if k is not None and len(out) >= k:
            break
    if k is not None and len(out) < k:
        raise MovingAIFormatError(f"{path} has {len(out)} agents, {k} requested")
    if not out:
        raise MovingAIFormatError(f"{path}: no agent lines")
    return out


def grid_graph(grid: GridMap) -> Tuple[sparse.csr_matrix, np.ndarray, np.ndarray]:
    """The 4-connected graph of the free cells.

    Returns ``(durations, cells, index)``: the CSR matrix (all durations 1), ``cells[node] =
    (row, col)`` and ``index[row, col] = node`` (-1 on blocked cells).
    """
    free = grid.free
    h, w = free.shape
    index = -np.ones((h, w), dtype=np.int64)
    rr, cc = np.nonzero(free)
    index[rr, cc] = np.arange(len(rr))
    cells = np.stack([rr, cc], axis=1)
    src_parts, dst_parts = [], []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        r2, c2 = rr + dr, cc + dc
        ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        ok[ok] = free[r2[ok], c2[ok]]
        src_parts.append(index[rr[ok], cc[ok]])
        dst_parts.append(index[r2[ok], c2[ok]])
    src = np.concatenate(src_parts)
    dst = np.concatenate(dst_parts)
    n = len(rr)
    m = sparse.csr_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
    return m, cells, index


@dataclass
class GridInstance:
    """A grid MAPF instance ready for :func:`agents.search.mapf.solve_cbs` (unit time)."""

    grid: GridMap
    agents: List[ScenAgent]
    graph: sparse.csr_matrix
    cells: np.ndarray
    index: np.ndarray
    starts: List[int] = field(default_factory=list)
    goals: List[int] = field(default_factory=list)

    def node(self, cell: Cell) -> int:
        """Graph node of a ``(row, col)`` cell."""
        r, c = cell
        if not (0 <= r < self.grid.height and 0 <= c < self.grid.width) or self.index[r, c] < 0:
            raise ValueError(f"cell (row={r}, col={c}) is blocked or off the {self.grid.height}x{self.grid.width} map")
        return int(self.index[r, c])

    def cell(self, node: int) -> Cell:
        """``(row, col)`` of a graph node."""
        r, c = self.cells[node]
        return int(r), int(c)

    def to_rowcol(self, paths: Sequence[Sequence]) -> List[List[List[int]]]:
        """Paths (node per time step, or ``(node, time)`` per time step) as ``[row, col]`` lists."""
        out = []
        for p in paths:
            seq = []
            for item in p:
                v = item[0] if isinstance(item, (tuple, list)) else item
                r, c = self.cells[int(v)]
                seq.append([int(r), int(c)])
            out.append(seq)
        return out


def check_scen_matches_map(agents: Sequence[ScenAgent], grid: GridMap, map_path: PathLike,
                           scen_path: PathLike) -> None:
    """``ValueError`` where a scenario line names another map (file name or size) than ``map_path``.

    MovingAI scenario lines carry the map's file name, width and height; a scenario of another
    map would otherwise run on cells that mean something else. The name is compared without
    folders (``maps/x.map`` names ``x.map``).
    """
    want = Path(map_path).name
    for i, a in enumerate(agents):
        named = Path(a.map_name.replace("\\", "/")).name
        if named and named != want:
            raise ValueError(f"{_where(scen_path, a)}: agent {i} belongs to map {a.map_name!r}, not {want!r}")
        if a.map_size != (0, 0) and a.map_size != (grid.width, grid.height):
            raise ValueError(f"{_where(scen_path, a)}: agent {i} is for a {a.map_size[0]}x{a.map_size[1]} map "
                             f"(width x height); {want} is {grid.width}x{grid.height}")


def _where(scen_path: PathLike, agent: ScenAgent) -> str:
    """``path:line`` of the scenario line an agent was read from (``path`` where not known)."""
    return f"{scen_path}:{agent.line}" if agent.line else str(scen_path)


def load_instance(map_path: PathLike, scen_path: PathLike, k: Optional[int] = None) -> GridInstance:
    """Load a map and the first ``k`` agents of a scenario as a :class:`GridInstance`."""
    grid = load_map(map_path)
    agents = load_scen(scen_path, k)
    check_scen_matches_map(agents, grid, map_path, scen_path)
    graph, cells, index = grid_graph(grid)
    inst = GridInstance(grid, agents, graph, cells, index)
    for i, a in enumerate(agents):
        for what, cell in (("start", a.start), ("goal", a.goal)):
            r, c = cell
            if not (0 <= r < grid.height and 0 <= c < grid.width) or index[r, c] < 0:
                raise ValueError(f"{_where(scen_path, a)}: agent {i} {what} (row={r}, col={c}) is not a free cell "
                                 f"of {map_path}")
    inst.starts = [inst.node(a.start) for a in agents]
    inst.goals = [inst.node(a.goal) for a in agents]
    return inst


__all__ = ["BLOCKED_CHARS", "FREE_CHARS", "GridInstance", "GridMap", "MovingAIFormatError", "ScenAgent",
           "check_scen_matches_map", "grid_graph", "load_instance", "load_map", "load_scen"]
