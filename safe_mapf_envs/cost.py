"""Exact distance to obstacles and the safety cost functions.

The cost of the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe
Reinforcement Learning" (its eq. 5) is ``C = 2 - 2h/r`` for ``0 <= h <= r`` and 0 beyond, with
``h`` the distance from the agent's centre to the boundary of the nearest obstacle and ``r``
the radius of influence. Distances are computed analytically against axis-aligned boxes,
vectorized over points and boxes.
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Optional, Sequence, Tuple

import numpy as np

from .checks import check_number, show

Box = Tuple[float, float, float, float]


def _linear(h: np.ndarray, r: float) -> np.ndarray:
    return np.where(h <= r, 2.0 - 2.0 * h / r, 0.0)


def _cosine(h: np.ndarray, r: float) -> np.ndarray:
    return np.where(h <= r, 1.0 + np.cos(np.pi * np.minimum(h, r) / r), 0.0)


def _constant(h: np.ndarray, r: float) -> np.ndarray:
    return np.where(h <= r, 1.0, 0.0)


#: Cost profiles as functions of the obstacle distance ``h`` and radius ``r``.
#: ``linear`` is the paper's (2 at contact, 0 at ``r``); ``cosine`` falls smoothly from 2 to 0;
#: ``constant`` is 1 anywhere within ``r``.
COST_FUNCTIONS: Dict[str, Callable[[np.ndarray, float], np.ndarray]] = {
    "linear": _linear,
    "cosine": _cosine,
    "constant": _constant,
}


_SCALAR = (_linear, _constant)  # profiles that :meth:`ObstacleField.peak_cost` computes in Python
_ZERO_BEYOND_RADIUS = (_linear, _cosine, _constant)  # profiles that are 0 for every h > r
#: Boxes and points x boxes from which the queries read only the boxes near each point (a
#: :class:`BoxIndex`, where each point has at most a quarter of the boxes near it): below them,
#: one dense NumPy computation over every box is faster.
INDEX_MIN_BOXES = 32
_INDEX_MIN_WORK = 1024


class BoxIndex:
    """Axis-aligned boxes bucketed by the cells of a uniform grid: each cell lists every box that
    comes within ``reach`` of it (a little more, against rounding), padded to one length with a
    far-away dummy box, so that the boxes near a batch of points are gathered in one step.

    Every box within ``reach`` of a point is among its cell's boxes, so the smallest distance
    to those is the true one wherever the true one is at most ``reach``, and larger than
    ``reach`` elsewhere; a box that contains the point is always among them.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, size: Tuple[float, float], reach: float) -> None:
        w, h = size
        pad = reach * (1.0 + 1e-6) + 1e-9
        self.x0 = min(0.0, float(lo[:, 0].min()))
        self.y0 = min(0.0, float(lo[:, 1].min()))
        x1 = max(w, float(hi[:, 0].max()))
        y1 = max(h, float(hi[:, 1].max()))
        self.cell = max(reach, (x1 - self.x0) / 256.0, (y1 - self.y0) / 256.0, 1e-9)
        self.nx = int((x1 - self.x0) / self.cell) + 1
        self.ny = int((y1 - self.y0) / self.cell) + 1
        # cells each box reaches, one more on every side (points on a cell border may round either way)
        ix0 = np.clip(np.floor((lo[:, 0] - pad - self.x0) / self.cell).astype(np.int64) - 1, 0, self.nx - 1)
        ix1 = np.clip(np.floor((hi[:, 0] + pad - self.x0) / self.cell).astype(np.int64) + 1, 0, self.nx - 1)
        iy0 = np.clip(np.floor((lo[:, 1] - pad - self.y0) / self.cell).astype(np.int64) - 1, 0, self.ny - 1)
        iy1 = np.clip(np.floor((hi[:, 1] + pad - self.y0) / self.cell).astype(np.int64) + 1, 0, self.ny - 1)
        diff = np.zeros((self.ny + 1, self.nx + 1), dtype=np.int64)  # 2D difference array of box counts
        np.add.at(diff, (iy0, ix0), 1)
        np.add.at(diff, (iy0, ix1 + 1), -1)
        np.add.at(diff, (iy1 + 1, ix0), -1)
        np.add.at(diff, (iy1 + 1, ix1 + 1), 1)
        counts = diff.cumsum(0).cumsum(1)[:-1, :-1]
        n = len(lo)
        #: the most boxes near one cell: every query measures this many per point
        self.width = width = max(int(counts.max()), 1)
        self.table = np.full((self.ny * self.nx, width), n, dtype=np.int32)  # n: the dummy box
        fill = np.zeros(self.ny * self.nx, dtype=np.int64)
        for b, (a0, a1, b0, b1) in enumerate(zip(ix0.tolist(), ix1.tolist(), iy0.tolist(), iy1.tolist())):
            cells = (np.arange(b0, b1 + 1)[:, None] * self.nx + np.arange(a0, a1 + 1)[None, :]).ravel()
            self.table[cells, fill[cells]] = b
            fill[cells] += 1
        far = np.full((1, 2), 1e150)  # farther than any point (no overflow squaring the gap), contains none
        self.lo = np.concatenate([lo, far])
        self.hi = np.concatenate([hi, far])

    def near(self, flat: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Corners ``(lo, hi)`` of the boxes near each point of ``flat`` ``(P, 2)``, each ``(P, K, 2)``."""
        x = np.where(np.isfinite(flat[:, 0]), flat[:, 0], self.x0)
        y = np.where(np.isfinite(flat[:, 1]), flat[:, 1], self.y0)
        ix = np.clip(np.floor((x - self.x0) / self.cell), 0, self.nx - 1).astype(np.int64)
        iy = np.clip(np.floor((y - self.y0) / self.cell), 0, self.ny - 1).astype(np.int64)
        ids = self.table[iy * self.nx + ix]
        return self.lo[ids], self.hi[ids]


class ObstacleField:
    """Distance and cost to a set of axis-aligned boxes inside a rectangular world.

    Args:
        boxes: obstacles as ``(x0, y0, x1, y1)`` in world units.
        size: world extent ``(width, height)``.
        cost_radius: radius of influence ``r`` (> 0).
        cost_fn: one of :data:`COST_FUNCTIONS`.
        boundary_cost: if ``True`` the outer boundary also counts as an obstacle for the cost
            (the paper's code does not; the boundary always confines the agent).
    """

    def __init__(
        self,
        boxes: Sequence[Box],
        size: Tuple[float, float],
        cost_radius: float,
        cost_fn: str = "linear",
        boundary_cost: bool = False,
    ) -> None:
        cost_radius = check_number(cost_radius, "cost_radius", strict=True)
        if cost_fn not in COST_FUNCTIONS:
            raise ValueError(f"unknown cost_fn {show(cost_fn)}; choose one of {sorted(COST_FUNCTIONS)}")
        self.boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        self.size = (float(size[0]), float(size[1]))
        self.cost_radius = float(cost_radius)
        self.cost_fn = cost_fn
        self.boundary_cost = bool(boundary_cost)
        self._fn = COST_FUNCTIONS[cost_fn]
        self._lo = self.boxes[:, :2]
        self._hi = self.boxes[:, 2:]
        self._box_list = [tuple(b) for b in self.boxes.tolist()]
        self._indexes: Dict[float, BoxIndex] = {}
        # where the cost is 0 beyond cost_radius, only the boxes within it are measured
        self._cost_reach = self.cost_radius if self._fn in _ZERO_BEYOND_RADIUS else np.inf

    def _index(self, reach: float, n_points: int) -> Optional[BoxIndex]:
        """The :class:`BoxIndex` of the boxes for ``reach`` (built on first use), where queries on
        ``n_points`` points are faster with it than over every box; else ``None``."""
        if len(self.boxes) < INDEX_MIN_BOXES or n_points * len(self.boxes) < _INDEX_MIN_WORK:
            return None
        index = self._indexes.get(reach)
        if index is None:
            index = self._indexes[reach] = BoxIndex(self._lo, self._hi, self.size, reach)
        return index if 4 * index.width <= len(self.boxes) else None

    def _box_distance(self, flat: np.ndarray, reach: float = np.inf) -> np.ndarray:
        """Distance from each point ``(P, 2)`` to the nearest box (``inf`` without boxes), exact
        wherever it is at most ``reach``; with a finite ``reach`` and many points and boxes only
        the boxes near each point are measured, and where all of them are farther than
        ``reach`` the result is some distance beyond ``reach`` (or ``inf``)."""
        if not len(self.boxes):
            return np.full(len(flat), np.inf)
        index = None
        if len(self.boxes) >= INDEX_MIN_BOXES and reach < np.inf:
            index = self._index(float(reach), len(flat))
        if index is not None:
            lo, hi = index.near(flat)
            gap = np.maximum(np.maximum(lo - flat[:, None], flat[:, None] - hi), 0.0)
        else:
            # Per-axis gap to each box, 0 when the coordinate lies within the box's span.
            gap = np.maximum(np.maximum(self._lo[None] - flat[:, None], flat[:, None] - self._hi[None]), 0.0)
        return np.sqrt((gap * gap).sum(-1)).min(-1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to the nearest obstacle boundary (0 inside an obstacle).

        ``points`` has shape ``(..., 2)``; the result has shape ``(...)``. Returns ``inf`` where
        there is nothing to measure against (no boxes and ``boundary_cost=False``).
        """
        return self._distance(points)

    def _distance(self, points: np.ndarray, reach: float = np.inf) -> np.ndarray:
        """:meth:`distance`, exact where at most ``reach`` (see :meth:`_box_distance`)."""
        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 2)
        d = self._box_distance(flat, reach)
        if self.boundary_cost:
            w, h = self.size
            wall = np.minimum(np.minimum(flat[:, 0], w - flat[:, 0]), np.minimum(flat[:, 1], h - flat[:, 1]))
            d = np.minimum(d, np.maximum(wall, 0.0))
        return d.reshape(p.shape[:-1])

    def inside(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """``True`` where a disc of radius ``margin`` at the point overlaps an obstacle or leaves the world."""
        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 2)
        w, h = self.size
        out = (flat[:, 0] < margin) | (flat[:, 0] > w - margin) | (flat[:, 1] < margin) | (flat[:, 1] > h - margin)
        if len(self.boxes):
            index = self._index(float(margin), len(flat)) if 0.0 <= margin < np.inf else None
            if index is not None:  # a box that contains a point is among its near ones
                lo, hi = index.near(flat)
            else:
                lo, hi = self._lo[None], self._hi[None]
            gap = np.maximum(np.maximum(lo - flat[:, None], flat[:, None] - hi), 0.0)
            d = np.sqrt((gap * gap).sum(-1)).min(-1)
            inside_box = ((flat[:, None] > lo) & (flat[:, None] < hi)).all(-1).any(-1)
            out |= inside_box | (d < margin)
        return out.reshape(p.shape[:-1])

    def cost_of_distance(self, h: np.ndarray) -> np.ndarray:
        """Apply the cost profile to obstacle distances ``h``."""
        return self._fn(np.asarray(h, dtype=np.float64), self.cost_radius)

    def cost(self, points: np.ndarray) -> np.ndarray:
        """Cost at each point, shape ``points.shape[:-1]``.

        The profiles of :data:`COST_FUNCTIONS` are 0 beyond ``cost_radius``, so with many
        points and boxes only the boxes within that radius of each point are measured (the
        same costs, for a fraction of the work on a large map).
        """
        return self._fn(self._distance(points, self._cost_reach), self.cost_radius)

    def peak_cost(self, points: np.ndarray) -> float:
        """The largest cost over ``points`` (shape ``(k, 2)``, ``k >= 1``): ``float(cost(points).max())``.

        A few points near a few boxes (one agent's sub-steps) are done in plain Python with
        the same arithmetic as :meth:`distance` and the ``linear`` and ``constant`` profiles,
        faster than NumPy's per-call overhead; the rest goes through :meth:`cost`.
        """
        p = np.asarray(points, dtype=np.float64)
        fn = self._fn
        if p.ndim != 2 or p.shape[1] != 2 or not 0 < len(p) * max(len(self._box_list), 1) <= 32 or fn not in _SCALAR:
            return float(self.cost(p).max())
        r = self.cost_radius
        w, h = self.size
        inf, isfinite = float("inf"), math.isfinite
        worst = -inf
        for x, y in p.tolist():
            if not (isfinite(x) and isfinite(y)):  # NaN and inf: as NumPy has them
                return float(self.cost(p).max())
            d = inf
            for x0, y0, x1, y1 in self._box_list:
                gx = max(max(x0 - x, x - x1), 0.0)
                gy = max(max(y0 - y, y - y1), 0.0)
                d = min(d, math.sqrt(gx * gx + gy * gy))
            if self.boundary_cost:
                d = min(d, max(min(min(x, w - x), min(y, h - y)), 0.0))
            c = (2.0 - 2.0 * d / r if fn is _linear else 1.0) if d <= r else 0.0
            worst = c if c > worst else worst
        return worst

    def cost_grid(self, resolution: float) -> np.ndarray:
        """Cost sampled at cell centres of a raster with ``resolution`` units per cell, shape ``(rows, cols)``."""
        w, h = self.size
        xs = (np.arange(int(np.ceil(w / resolution))) + 0.5) * resolution
        ys = (np.arange(int(np.ceil(h / resolution))) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        return self.cost(np.stack([gx, gy], -1))


__all__ = ["COST_FUNCTIONS", "ObstacleField"]
