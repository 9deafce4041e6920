"""What the single- and multi-agent environments share: a layout, its cost field, free-space
sampling, input checks and the ground-truth geodesic oracle.
"""
from __future__ import annotations

from typing import Optional, Protocol, Sequence, Tuple

import numpy as np

from .cost import ObstacleField
from .geodesic import GeodesicOracle
from .maps import get_map


class Layout(Protocol):
    """Anything with a name, a world size, static boxes and a default cost radius."""

    name: str
    cost_radius: float

    @property
    def size(self) -> Tuple[float, float]: ...

    def boxes(self) -> Sequence[Tuple[float, float, float, float]]: ...


def resolve_layout(layout) -> Layout:
    """Accept a layout object or the name of a registered map."""
    if isinstance(layout, str):
        return get_map(layout)
    return layout


class NavigationScenario:
    """A layout with its cost and the helpers every environment needs.

    Args:
        layout: a map name (see :data:`safe_mapf_envs.maps.MAPS`) or a :class:`Layout`.
        agent_radius: radius of the circular agents, in world units.
        cost_radius: radius of influence ``r`` of the cost; default: the layout's.
        cost_fn: ``"linear"`` (the paper's), ``"cosine"`` or ``"constant"``.
        boundary_cost: whether the outer boundary induces cost.
        geodesic_resolution: raster cell size of the ground-truth geodesic oracle; default
            a fifth of a grid cell (or 0.2 units).
    """

    def __init__(
        self,
        layout,
        agent_radius: float = 0.5,
        cost_radius: Optional[float] = None,
        cost_fn: str = "linear",
        boundary_cost: bool = False,
        geodesic_resolution: Optional[float] = None,
    ) -> None:
        self.layout = resolve_layout(layout)
        if not np.isfinite(agent_radius) or agent_radius <= 0:
            raise ValueError(f"agent_radius must be a positive number, got {agent_radius!r}")
        self.agent_radius = float(agent_radius)
        self.size = tuple(float(s) for s in self.layout.size)
        self.size_arr = np.array(self.size, dtype=np.float64)
        self.boxes = list(self.layout.boxes())
        r = self.layout.cost_radius if cost_radius is None else cost_radius
        self.field = ObstacleField(self.boxes, self.size, r, cost_fn=cost_fn, boundary_cost=boundary_cost)
        if geodesic_resolution is None:
            geodesic_resolution = getattr(self.layout, "resize_factor", 1.0) / 5.0
        self._geodesic_resolution = float(geodesic_resolution)
        self._oracle: Optional[GeodesicOracle] = None

    @property
    def oracle(self) -> GeodesicOracle:
        """The ground-truth geodesic oracle (built on first use)."""
        if self._oracle is None:
            self._oracle = GeodesicOracle(self.field, self.agent_radius, self._geodesic_resolution)
        return self._oracle

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """``True`` where an agent centred at the point overlaps no obstacle and stays inside the world."""
        return ~self.field.inside(points, margin=self.agent_radius)

    def check_position(self, point, what: str) -> np.ndarray:
        """Validate a user-given position; return it as a float array or raise ``ValueError``."""
        p = np.asarray(point, dtype=np.float64)
        if p.shape != (2,):
            raise ValueError(f"{what} must be an (x, y) pair, got shape {p.shape}: {point!r}")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{what} must be finite, got {point!r}")
        w, h = self.size
        if not (0.0 <= p[0] <= w and 0.0 <= p[1] <= h):
            raise ValueError(f"{what} {tuple(p)} lies outside the {w:g} x {h:g} world")
        if not self.is_free(p):
            raise ValueError(
                f"{what} {tuple(p)} is inside an obstacle or closer than the agent radius "
                f"{self.agent_radius:g} to one"
            )
        return p

    def sample_states(
        self,
        n: int,
        rng: np.random.Generator,
        max_cost: Optional[float] = None,
    ) -> np.ndarray:
        """Sample ``n`` free positions uniformly, optionally only where the cost is at most ``max_cost``.

        Returns an ``(n, 2)`` array in world units.
        """
        out = np.empty((0, 2))
        for _ in range(1000):
            cand = rng.uniform(0.0, 1.0, size=(max(2 * (n - len(out)), 16), 2)) * self.size_arr
            ok = self.is_free(cand)
            if max_cost is not None:
                ok &= self.field.cost(cand) <= max_cost
            out = np.concatenate([out, cand[ok]])
            if len(out) >= n:
                return out[:n]
        raise ValueError(
            f"could not sample {n} free states"
            + (f" with cost <= {max_cost}" if max_cost is not None else "")
            + f" on {self.layout.name}"
        )

    def sample_goal_in_band(self, start: np.ndarray, band: Tuple[float, float], rng: np.random.Generator) -> np.ndarray:
        """Sample a free goal whose ground-truth geodesic distance from ``start`` lies in ``band``."""
        lo, hi = float(band[0]), float(band[1])
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or hi < lo:
            raise ValueError(f"goal_distance must be a (lo, hi) band with 0 <= lo <= hi, got {band!r}")
        oracle = self.oracle
        cells, _ = oracle.band_cells(start, lo, hi)
        if len(cells) == 0:
            raise ValueError(f"no free goal at geodesic distance in [{lo:g}, {hi:g}] from start {tuple(start)}")
        centres = oracle.centres.reshape(-1, 2)
        res = oracle.resolution
        for _ in range(100):
            cell = cells[rng.integers(len(cells))]
            goal = centres[cell] + rng.uniform(-0.5, 0.5, size=2) * res
            if self.is_free(goal):
                d = float(oracle.distance(start, goal))
                if lo <= d <= hi:
                    return goal
        # the cell centres themselves are free; fall back to one of them
        return centres[cells[rng.integers(len(cells))]].copy()

    def geodesic_distance(self, a, b) -> np.ndarray:
        """Ground-truth shortest collision-free path length from ``a`` to ``b`` (``b`` may be ``(..., 2)``)."""
        return self.oracle.distance(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))


__all__ = ["Layout", "NavigationScenario", "resolve_layout"]
