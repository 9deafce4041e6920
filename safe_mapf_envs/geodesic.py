"""Ground-truth geodesic (shortest collision-free path) distances, for evaluation only.

Agents and planners never see these: they exist to generate problems of a given difficulty,
to measure how well learned distances match reality, and for tests.

The free space (points whose clearance from every obstacle and the outer boundary is at least
the agent radius) is rasterised at ``resolution`` units per cell and searched with Dijkstra on
a 16-connected grid (king and knight moves, each checked against the obstacles), whose paths
are within about 3% of the true any-angle length. Pairs that see each other directly get the
exact straight-line distance.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Tuple

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .cost import ObstacleField

_MOVES = [(0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1),
          (1, 2), (2, 1), (-1, 2), (-2, 1), (1, -2), (2, -1), (-1, -2), (-2, -1)]


class GeodesicOracle:
    """Shortest-path distances in the free space of an :class:`~safe_mapf_envs.cost.ObstacleField`.

    Args:
        field: the obstacles and world size.
        agent_radius: clearance an agent's centre keeps from obstacles.
        resolution: raster cell size in world units.
        cache_size: number of single-source distance rows kept in memory.
    """

    def __init__(self, field: ObstacleField, agent_radius: float, resolution: float, cache_size: int = 256) -> None:
        self.field = field
        self.agent_radius = float(agent_radius)
        self.resolution = float(resolution)
        w, h = field.size
        self.cols = int(np.ceil(w / resolution))
        self.rows = int(np.ceil(h / resolution))
        xs = (np.arange(self.cols) + 0.5) * resolution
        ys = (np.arange(self.rows) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        self.centres = np.stack([gx, gy], -1)  # (rows, cols, 2)
        self.free = ~field.inside(self.centres, margin=self.agent_radius)
        self._graph = self._build_graph()
        self._cache: "OrderedDict[int, np.ndarray]" = OrderedDict()
        self._cache_size = cache_size

    def _build_graph(self) -> csr_matrix:
        rows, cols, free = self.rows, self.cols, self.free
        idx = np.arange(rows * cols).reshape(rows, cols)
        src, dst, wts = [], [], []
        for di, dj in _MOVES:
            # cells a move passes through: for a knight move, the two cells beside its segment
            via = [(di, dj)]
            si, sj = int(np.sign(di)), int(np.sign(dj))
            if di and dj:  # diagonal and knight moves must not cut a blocked corner
                via += [(si, 0), (0, sj), (si, sj)]
            lo_i = min(v[0] for v in via + [(0, 0)])
            hi_i = max(v[0] for v in via + [(0, 0)])
            lo_j = min(v[1] for v in via + [(0, 0)])
            hi_j = max(v[1] for v in via + [(0, 0)])
            i0, i1 = -lo_i, rows - hi_i
            j0, j1 = -lo_j, cols - hi_j
            ok = free[i0:i1, j0:j1].copy()
            for vi, vj in via:
                ok &= free[i0 + vi:i1 + vi, j0 + vj:j1 + vj]
            a = idx[i0:i1, j0:j1][ok]
            b = idx[i0 + di:i1 + di, j0 + dj:j1 + dj][ok]
            src.append(a)
            dst.append(b)
            wts.append(np.full(len(a), np.hypot(di, dj) * self.resolution))
        n = rows * cols
        return csr_matrix((np.concatenate(wts), (np.concatenate(src), np.concatenate(dst))), shape=(n, n))

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Flat index of the free raster cell nearest to each point (shape ``points.shape[:-1]``)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        j = np.clip((p[:, 0] / self.resolution).astype(int), 0, self.cols - 1)
        i = np.clip((p[:, 1] / self.resolution).astype(int), 0, self.rows - 1)
        cells = i * self.cols + j
        bad = ~self.free.reshape(-1)[cells]
        if bad.any():
            free_idx = np.flatnonzero(self.free.reshape(-1))
            fc = self.centres.reshape(-1, 2)[free_idx]
            d = ((p[bad][:, None] - fc[None]) ** 2).sum(-1)
            cells[bad] = free_idx[d.argmin(1)]
        return cells.reshape(np.asarray(points).shape[:-1])

    def distances_from_cell(self, cell: int) -> np.ndarray:
        """Graph distances from raster cell ``cell`` to every cell (``inf`` where unreachable)."""
        cell = int(cell)
        row = self._cache.get(cell)
        if row is None:
            row = dijkstra(self._graph, directed=True, indices=cell)
            self._cache[cell] = row
            if len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(cell)
        return row

    def visible(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``True`` where the straight segment from ``a`` to ``b`` keeps the agent's clearance."""
        a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
        a, b = np.broadcast_arrays(a, b)
        n_samples = int(np.ceil(np.max(np.linalg.norm(b - a, axis=-1), initial=0.0) / (0.25 * self.resolution))) + 2
        t = np.linspace(0.0, 1.0, n_samples)[:, None, None]
        pts = a[None] + t * (b - a)[None]
        return np.asarray(~self.field.inside(pts, margin=self.agent_radius * 0.999).any(0))

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Geodesic distance from ``a`` to each of ``b`` (``b`` shape ``(..., 2)``), in world units."""
        a = np.asarray(a, dtype=np.float64).reshape(2)
        bb = np.asarray(b, dtype=np.float64)
        flat = bb.reshape(-1, 2)
        row = self.distances_from_cell(int(self.cell_of(a)))
        cells = self.cell_of(flat)
        centres = self.centres.reshape(-1, 2)
        d = (row[cells] + np.linalg.norm(flat - centres[cells], axis=-1)
             + np.linalg.norm(a - centres[int(self.cell_of(a))]))
        vis = self.visible(a[None], flat)
        d = np.where(vis, np.linalg.norm(flat - a, axis=-1), d)
        return d.reshape(bb.shape[:-1])

    def band_cells(self, start: np.ndarray, lo: float, hi: float) -> Tuple[np.ndarray, np.ndarray]:
        """Free raster cells whose graph distance from ``start`` lies in ``[lo, hi]``: (cell ids, distances)."""
        row = self.distances_from_cell(int(self.cell_of(start)))
        ok = np.flatnonzero((row >= lo) & (row <= hi))
        return ok, row[ok]

    @property
    def max_distance(self) -> float:
        """The largest finite geodesic distance between two free cells (sampled from a few sources)."""
        free_idx = np.flatnonzero(self.free.reshape(-1))
        if not len(free_idx):
            return 0.0
        rng = np.random.default_rng(0)
        srcs = rng.choice(free_idx, size=min(16, len(free_idx)), replace=False)
        best = 0.0
        for s in srcs:
            row = dijkstra(self._graph, directed=True, indices=int(s))
            far = int(np.argmax(np.where(np.isfinite(row), row, -1)))
            row2 = dijkstra(self._graph, directed=True, indices=far)
            best = max(best, float(np.max(row2[np.isfinite(row2)])))
        return best


__all__ = ["GeodesicOracle"]
