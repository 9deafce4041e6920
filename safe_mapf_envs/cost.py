"""Exact distance to obstacles and the safety cost functions.

The cost of the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe
Reinforcement Learning" (its eq. 5) is ``C = 2 - 2h/r`` for ``0 <= h <= r`` and 0 beyond, with
``h`` the distance from the agent's centre to the boundary of the nearest obstacle and ``r``
the radius of influence. Distances are computed analytically against axis-aligned boxes,
vectorized over points and boxes.
"""
from __future__ import annotations

from typing import Callable, Dict, Sequence, Tuple

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

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to the nearest obstacle boundary (0 inside an obstacle).

        ``points`` has shape ``(..., 2)``; the result has shape ``(...)``. Returns ``inf`` where
        there is nothing to measure against (no boxes and ``boundary_cost=False``).
        """
        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 2)
        if len(self.boxes):
            # Per-axis gap to each box, 0 when the coordinate lies within the box's span.
            gap = np.maximum(np.maximum(self._lo[None] - flat[:, None], flat[:, None] - self._hi[None]), 0.0)
            d = np.sqrt((gap * gap).sum(-1)).min(-1)
        else:
            d = np.full(len(flat), np.inf)
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
            gap = np.maximum(np.maximum(self._lo[None] - flat[:, None], flat[:, None] - self._hi[None]), 0.0)
            d = np.sqrt((gap * gap).sum(-1)).min(-1)
            inside_box = ((flat[:, None] > self._lo[None]) & (flat[:, None] < self._hi[None])).all(-1).any(-1)
            out |= inside_box | (d < margin)
        return out.reshape(p.shape[:-1])

    def cost_of_distance(self, h: np.ndarray) -> np.ndarray:
        """Apply the cost profile to obstacle distances ``h``."""
        return self._fn(np.asarray(h, dtype=np.float64), self.cost_radius)

    def cost(self, points: np.ndarray) -> np.ndarray:
        """Cost at each point, shape ``points.shape[:-1]``."""
        return self.cost_of_distance(self.distance(points))

    def cost_grid(self, resolution: float) -> np.ndarray:
        """Cost sampled at cell centres of a raster with ``resolution`` units per cell, shape ``(rows, cols)``."""
        w, h = self.size
        xs = (np.arange(int(np.ceil(w / resolution))) + 0.5) * resolution
        ys = (np.arange(int(np.ceil(h / resolution))) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        return self.cost(np.stack([gx, gy], -1))


__all__ = ["COST_FUNCTIONS", "ObstacleField"]
