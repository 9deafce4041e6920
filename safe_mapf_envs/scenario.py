"""What the single- and multi-agent environments share: a layout, its cost field, free-space
sampling, input checks and the ground-truth geodesic oracle.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Protocol, Sequence, Tuple

import numpy as np

from .checks import check_band, check_count, check_number, plural, show, show_point
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


#: Largest share of an area that discs placed uniformly at random, without overlap, cover: random
#: sequential placement jams at about 0.547 of the plane (Feder, 1980). Sampling more agents
#: than this share allows is hopeless, however long it runs.
RANDOM_FILL = 0.55

#: :meth:`NavigationScenario.packing` results by map and arguments (environments built on one map
#: share them), at most :data:`_PACKINGS_KEPT`, the oldest dropped first.
_PACKINGS: Dict[Tuple[Any, ...], np.ndarray] = {}
_PACKINGS_KEPT = 64


def resolve_layout(layout) -> Layout:
    """Accept a layout object or the name of a registered map."""
    if isinstance(layout, str):
        return get_map(layout)
    return layout


def union_area(boxes: np.ndarray) -> float:
    """Exact area of the union of axis-aligned boxes ``(x0, y0, x1, y1)`` (empty ones are ignored)."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    b = b[(b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1])]
    if not len(b):
        return 0.0
    xs, ys = np.unique(b[:, [0, 2]]), np.unique(b[:, [1, 3]])
    covered = np.zeros((len(xs) - 1, len(ys) - 1), dtype=bool)
    ix, iy = np.searchsorted(xs, b[:, [0, 2]]), np.searchsorted(ys, b[:, [1, 3]])
    for (i0, i1), (j0, j1) in zip(ix, iy):
        covered[i0:i1, j0:j1] = True
    return float(np.diff(xs) @ covered @ np.diff(ys))


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
        self.agent_radius = check_number(agent_radius, "agent_radius", strict=True)
        w, h = self.layout.size
        self.size: Tuple[float, float] = (float(w), float(h))
        self.size_arr = np.array(self.size, dtype=np.float64)
        self.boxes = list(self.layout.boxes())
        r = self.layout.cost_radius if cost_radius is None else cost_radius
        self.field = ObstacleField(self.boxes, self.size, r, cost_fn=cost_fn, boundary_cost=boundary_cost)
        if geodesic_resolution is None:
            geodesic_resolution = getattr(self.layout, "resize_factor", 1.0) / 5.0
        self._geodesic_resolution = float(geodesic_resolution)
        self._oracle: Optional[GeodesicOracle] = None
        self._areas: Dict[float, float] = {}  # area_around_free by reach (placement asks at every reset)

    @property
    def oracle(self) -> GeodesicOracle:
        """The ground-truth geodesic oracle (built on first use)."""
        if self._oracle is None:
            self._oracle = GeodesicOracle(self.field, self.agent_radius, self._geodesic_resolution)
        return self._oracle

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """``True`` where an agent centred at the point overlaps no obstacle and stays inside the world."""
        return ~self.field.inside(points, margin=self.agent_radius)

    def _as_points(self, points, what: str) -> np.ndarray:
        """``points`` as a finite float array of shape ``(..., 2)``, or ``ValueError`` naming ``what``."""
        try:
            raw = np.asarray(points)
            if raw.dtype.kind == "c":
                raise TypeError("complex")
            p = raw.astype(np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be real (x, y) positions, got {show(points)}") from None
        if p.ndim == 0 or p.shape[-1] != 2:
            raise ValueError(f"{what} must be an (x, y) pair or an array of them (..., 2), got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{what} must be finite, got {show(points)}")
        return p

    def check_position(self, point, what: str) -> np.ndarray:
        """Validate a user-given position; return it as a float array or raise ``ValueError``."""
        try:
            raw = np.asarray(point)
            p = raw.astype(np.float64) if raw.dtype.kind != "c" else None
        except (TypeError, ValueError):
            p = None
        if p is None:
            raise ValueError(f"{what} must be a real (x, y) pair, got {show(point)}")
        if p.shape != (2,):
            raise ValueError(f"{what} must be an (x, y) pair, got shape {p.shape}: {show(point)}")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{what} must be finite, got {show(point)}")
        w, h = self.size
        if not (0.0 <= p[0] <= w and 0.0 <= p[1] <= h):
            raise ValueError(f"{what} {show_point(p)} lies outside the {w:g} x {h:g} world")
        if not self.is_free(p):
            raise ValueError(
                f"{what} {show_point(p)} is inside an obstacle or closer than the agent radius "
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

        Returns an ``(n, 2)`` array in world units; ``n`` must be an integer >= 0.
        """
        n = check_count(n, "n", 0)
        if max_cost is not None:
            max_cost = check_number(max_cost, "max_cost")
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
            f"could not sample {plural(n, 'free state')}"
            + (f" with cost <= {max_cost:g}" if max_cost is not None else "")
            + f" on {self.layout.name}"
        )

    def _bridges(self, n: int, rng: np.random.Generator, bridge: Optional[float]) -> Tuple[np.ndarray, np.ndarray]:
        """``n`` successful bridge tests: their centres ``(n, 2)`` and unit directions ``(n, 2)``."""
        n = check_count(n, "n", 0)
        length = 5.0 * self.agent_radius if bridge is None else check_number(bridge, "bridge", strict=True)
        centres, directions = np.empty((0, 2)), np.empty((0, 2))
        for _ in range(200):
            m = max(64 * (n - len(centres)), 256)
            centre = rng.uniform(0.0, 1.0, size=(m, 2)) * self.size_arr
            angle = rng.uniform(0.0, np.pi, size=m)
            unit = np.stack([np.cos(angle), np.sin(angle)], axis=1)
            half = 0.5 * length * unit
            ok = self.is_free(centre) & ~self.is_free(centre + half) & ~self.is_free(centre - half)
            centres, directions = np.concatenate([centres, centre[ok]]), np.concatenate([directions, unit[ok]])
            if len(centres) >= n:
                return centres[:n], directions[:n]
        raise ValueError(f"could not sample {plural(n, 'narrow-passage state')} on {self.layout.name} "
                         f"with a bridge of {length:g} units: the map has no passage that narrow")

    def sample_narrow_states(self, n: int, rng: np.random.Generator, bridge: Optional[float] = None) -> np.ndarray:
        """Sample ``n`` free positions in narrow passages (doorways, corridors, gaps between furniture).

        The bridge test of probabilistic roadmaps (Hsu et al., 2003): a segment of length
        ``bridge`` with a random centre and direction is kept when both of its ends are blocked
        (inside an obstacle, closer than the agent radius to one, or outside the world) and its
        centre is free; the centre is the sample. Uniform sampling seldom lands in a passage a
        little wider than an agent, and agents trained on uniform problems seldom learn to enter
        one. ``bridge`` defaults to five agent radii (1 m on the apartments), which finds
        passages up to about ``bridge + 2 * agent_radius`` wide across.

        Returns an ``(n, 2)`` array in world units; ``ValueError`` when the map has no such
        passage (after many tries).
        """
        return self._bridges(n, rng, bridge)[0]

    def sample_narrow_crossings(
        self, n: int, rng: np.random.Generator, reach: Tuple[float, float], bridge: Optional[float] = None
    ) -> Tuple[np.ndarray, np.ndarray]:
        """``n`` start-goal pairs that go through a narrow passage: ``(starts, goals)``, each ``(n, 2)``.

        Each pair lies on a line through a bridge-test centre (:meth:`sample_narrow_states`),
        across the bridge, i.e. along the passage: start and goal at distances drawn from
        ``reach = (lo, hi)`` (world units) on either side, in random order, with the straight
        segment between them free. A critic that has never been through a passage reads such
        goals as unreachable, so a sampler that chooses problems by predicted distance never
        picks them; these pairs are drawn without asking it.
        """
        n = check_count(n, "n", 0)
        lo, hi = check_band(reach)
        starts, goals = np.empty((0, 2)), np.empty((0, 2))
        for _ in range(200):
            m = max(4 * (n - len(starts)), 16)
            centre, unit = self._bridges(m, rng, bridge)
            along = np.stack([-unit[:, 1], unit[:, 0]], axis=1)
            a = centre - rng.uniform(lo, hi, size=(m, 1)) * along
            b = centre + rng.uniform(lo, hi, size=(m, 1)) * along
            t = np.linspace(0.0, 1.0, 16)
            path = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
            ok = self.is_free(path.reshape(-1, 2)).reshape(m, len(t)).all(axis=1)
            flip = rng.random(m) < 0.5
            a, b = np.where(flip[:, None], b, a), np.where(flip[:, None], a, b)
            starts, goals = np.concatenate([starts, a[ok]]), np.concatenate([goals, b[ok]])
            if len(starts) >= n:
                return starts[:n], goals[:n]
        raise ValueError(f"could not sample {plural(n, 'narrow-passage crossing')} on {self.layout.name} "
                         f"reaching {lo:g}-{hi:g} units from the passage")

    def sample_goal_in_band(self, start: np.ndarray, band: Tuple[float, float], rng: np.random.Generator) -> np.ndarray:
        """Sample a free goal whose ground-truth geodesic distance from ``start`` lies in ``band``."""
        lo, hi = check_band(band)
        oracle = self.oracle
        start_cell = int(oracle.cell_of(start))
        row = self._graph_distances_within(start_cell, hi)
        cells = np.flatnonzero((row >= lo) & (row <= hi))
        if len(cells) == 0:
            raise ValueError(f"no free goal at geodesic distance in [{lo:g}, {hi:g}] from start {show_point(start)}")
        centres = oracle.centres.reshape(-1, 2)
        res = oracle.resolution
        for _ in range(100):
            cell = cells[rng.integers(len(cells))]
            goal = centres[cell] + rng.uniform(-0.5, 0.5, size=2) * res
            if self.is_free(goal):
                d = self._geodesic_within(row, start, start_cell, goal)
                if lo <= d <= hi:
                    return goal
        # the cell centres themselves are free; fall back to one of them
        return centres[cells[rng.integers(len(cells))]].copy()

    def _graph_distances_within(self, cell: int, limit: float) -> np.ndarray:
        """The oracle's graph distances from raster cell ``cell`` (:meth:`GeodesicOracle.distances_from_cell
        <safe_mapf_envs.geodesic.GeodesicOracle.distances_from_cell>`) up to ``limit``, ``inf`` beyond.

        Dijkstra's search stops at ``limit``: every distance up to it is the full search's
        (each is the sum along the same shortest path), at a fraction of the cost for a goal band
        much shorter than the map.
        """
        from scipy.sparse.csgraph import dijkstra

        return dijkstra(self.oracle._graph, directed=True, indices=cell, limit=limit)

    def _geodesic_within(self, row: np.ndarray, start: np.ndarray, start_cell: int, goal: np.ndarray) -> float:
        """:meth:`GeodesicOracle.distance <safe_mapf_envs.geodesic.GeodesicOracle.distance>` from
        ``start`` to one ``goal`` with the row of :meth:`_graph_distances_within` (the same arithmetic).

        Where the row stops short of the goal's cell the result is ``inf`` instead of a finite
        distance beyond the row's limit, unless the goal is in sight (then both are the
        straight-line length): either way beyond the limit.
        """
        oracle = self.oracle
        a = np.asarray(start, dtype=np.float64).reshape(2)
        flat = np.asarray(goal, dtype=np.float64).reshape(-1, 2)
        cells = oracle.cell_of(flat)
        centres = oracle.centres.reshape(-1, 2)
        d = row[cells] + np.linalg.norm(flat - centres[cells], axis=-1) + np.linalg.norm(a - centres[start_cell])
        vis = oracle.visible(a[None], flat)
        return float(np.where(vis, np.linalg.norm(flat - a, axis=-1), d)[0])

    def geodesic_distance(self, a, b) -> np.ndarray:
        """Ground-truth shortest collision-free path length from ``a`` to ``b`` (``b`` may be ``(..., 2)``).

        Points closer to an obstacle than the agent radius are measured from the nearest
        position an agent can take; points outside the world or inside an obstacle raise
        ``ValueError`` (there is no path to them).
        """
        pa = self._as_points(a, "geodesic_distance: a")
        if pa.shape != (2,):
            raise ValueError(f"geodesic_distance: a must be one (x, y) pair, got shape {pa.shape}")
        pb = self._as_points(b, "geodesic_distance: b")
        for name, p in (("a", pa), ("b", pb)):
            bad = self.field.inside(p.reshape(-1, 2))
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                q = p.reshape(-1, 2)[k]
                where = name if p.ndim == 1 else f"{name}[{', '.join(map(str, np.unravel_index(k, p.shape[:-1])))}]"
                w, h = self.size
                reason = (f"lies outside the {w:g} x {h:g} world" if not (0 <= q[0] <= w and 0 <= q[1] <= h)
                          else "is inside an obstacle")
                raise ValueError(f"geodesic_distance: {where} = {show_point(q)} {reason}")
        return self.oracle.distance(pa, pb)

    # ----------------------------------------------------------------- capacity
    def max_agents(self, separation: float, fill: float = 1.0) -> int:
        """An upper bound on how many free positions fit at least ``separation`` apart.

        Discs of radius ``separation / 2`` around such positions do not overlap and lie in
        the world grown by ``separation / 2 - agent_radius`` less the obstacles shrunk by as
        much, so their number is at most ``fill`` times that area over a disc's area.
        ``fill=1`` bounds every arrangement; :data:`RANDOM_FILL` bounds random sampling.

        Args:
            separation: smallest distance between positions, at least ``2 * agent_radius``.
            fill: the share of the area the discs can cover, in ``(0, 1]``.
        """
        s = float(separation)
        if not s >= 2.0 * self.agent_radius:
            raise ValueError(f"separation must be at least 2 * agent_radius = {2.0 * self.agent_radius:g}, got {s:g}")
        return int(np.floor(fill * self.area_around_free(s / 2.0) / (np.pi * s * s / 4.0)))

    def area_around_free(self, reach: float) -> float:
        """An upper bound on the area within ``reach`` (>= agent radius) of the free positions."""
        key = float(reach)
        area = self._areas.get(key)
        if area is None:
            area = self._areas[key] = self._area_around_free(key)
        return area

    def _area_around_free(self, reach: float) -> float:
        e = float(reach) - self.agent_radius
        w, h = self.size
        shrunk = self.field.boxes + np.array([e, e, -e, -e])
        shrunk[:, :2] = np.maximum(shrunk[:, :2], -e)
        shrunk[:, 2] = np.minimum(shrunk[:, 2], w + e)
        shrunk[:, 3] = np.minimum(shrunk[:, 3], h + e)
        return (w + 2 * e) * (h + 2 * e) - union_area(shrunk)

    # ----------------------------------------------------------------- separated placement
    def _allowed(self, points: np.ndarray, max_cost: Optional[float]) -> np.ndarray:
        """``True`` where a position is free and, with ``max_cost``, costs at most that much
        (``points`` of shape ``(k, 2)``, checked in chunks to bound the memory)."""
        ok = np.empty(len(points), dtype=bool)
        for i in range(0, len(points), 1 << 15):
            chunk = points[i:i + (1 << 15)]
            ok[i:i + len(chunk)] = self.is_free(chunk)
            if max_cost is not None:
                ok[i:i + len(chunk)] &= self.field.cost(chunk) <= max_cost
        return ok

    def packing(self, separation: float, max_cost: Optional[float] = None) -> np.ndarray:
        """Free positions at least ``separation`` apart, as many as a deterministic packing finds.

        The larger of two packings: the densest of 32 hexagonal lattices (two orientations, 16
        offsets) with its gaps filled greedily, and a greedy scan of a grid of an eighth of
        ``separation`` row by row (or column by column), which follows corridors and furniture.
        With ``max_cost``, only positions whose cost is at most that value. The result depends on
        the map and the arguments alone; it is cached, and read-only, shape ``(k, 2)``.
        :meth:`sample_separated` places up to ``k`` positions on every call.
        """
        sep = check_number(separation, "separation", strict=True)
        if not sep >= 2.0 * self.agent_radius:
            raise ValueError(
                f"separation must be at least 2 * agent_radius = {2.0 * self.agent_radius:g}, got {sep:g}"
            )
        if max_cost is not None:
            max_cost = check_number(max_cost, "max_cost")
        f = self.field
        key = (self.size, tuple(map(tuple, f.boxes.tolist())), self.agent_radius, sep, max_cost,
               None if max_cost is None else (f.cost_radius, f.cost_fn, f.boundary_cost))
        pts = _PACKINGS.get(key)
        if pts is None:
            s = sep * (1.0 + 1e-9)  # a margin over rounding: packed positions are never closer than sep
            lattice = self._lattice(s, max_cost)
            found = [
                self._greedy_scan(s, max_cost, lattice, across=False),
                self._greedy_scan(s, max_cost, np.zeros((0, 2)), across=False),
                self._greedy_scan(s, max_cost, np.zeros((0, 2)), across=True),
            ]
            pts = max(found, key=len)
            pts.setflags(write=False)
            if len(_PACKINGS) >= _PACKINGS_KEPT:
                _PACKINGS.pop(next(iter(_PACKINGS)))
            _PACKINGS[key] = pts
        return pts

    def capacity(self, separation: float, max_cost: Optional[float] = None) -> int:
        """How many free positions :meth:`sample_separated` places at least ``separation`` apart
        (with ``max_cost``: costing at most that much), on every call: ``len(packing(...))``."""
        return len(self.packing(separation, max_cost))

    def _allowed_grid(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """:meth:`is_free` on the grid of ``xs`` by ``ys``, shape ``(len(ys), len(xs))``, box by box
        (the same arithmetic as :meth:`ObstacleField.inside <safe_mapf_envs.cost.ObstacleField.inside>`)."""
        r = self.agent_radius
        w, h = self.size
        free = ~(((ys < r) | (ys > h - r))[:, None] | ((xs < r) | (xs > w - r))[None, :])
        # A box blocks only the points within r of it: the window of the grid that it reaches,
        # a little more (against rounding); beyond it one gap alone exceeds r.
        pad = r * (1.0 + 1e-6) + 1e-9
        for x0, y0, x1, y1 in self.field.boxes.tolist():
            j0, j1 = np.searchsorted(xs, x0 - pad, "left"), np.searchsorted(xs, x1 + pad, "right")
            i0, i1 = np.searchsorted(ys, y0 - pad, "left"), np.searchsorted(ys, y1 + pad, "right")
            if j0 >= j1 or i0 >= i1:
                continue
            bx, by = xs[j0:j1], ys[i0:i1]
            gx = np.maximum(np.maximum(x0 - bx, bx - x1), 0.0)
            gy = np.maximum(np.maximum(y0 - by, by - y1), 0.0)
            free[i0:i1, j0:j1] &= np.sqrt(gy[:, None] * gy[:, None] + gx[None, :] * gx[None, :]) >= r
        return free

    def check_agent_count(self, n: int, min_separation: float, max_start_cost: Optional[float] = None) -> int:
        """The capacity for agents whose sampled starts (costing at most ``max_start_cost``) and goals
        are ``min_separation`` apart; ``ValueError`` naming ``n`` and the capacity if ``n`` exceeds it."""
        fit = self.capacity(min_separation)
        if max_start_cost is not None:
            fit = min(fit, self.capacity(min_separation, max_start_cost))
        if n > fit:
            cheap = "" if max_start_cost is None else f" (starts with cost <= {max_start_cost:g})"
            raise ValueError(
                f"n_agents={n} cannot fit on {self.layout.name}: its capacity is {plural(fit, 'agent')} of radius "
                f"{self.agent_radius:g} with starts and goals at least min_separation={min_separation:g} apart{cheap}; "
                f"use at most {fit} agents or a smaller min_separation (the least is 2 * agent_radius = "
                f"{2.0 * self.agent_radius:g})"
            )
        return fit

    def _lattice(self, s: float, max_cost: Optional[float]) -> np.ndarray:
        """The allowed points of the hexagonal lattice of spacing ``s`` that has the most of them,
        of two orientations and 4 x 4 offsets, anchored at the free border ``agent_radius`` in."""
        r = self.agent_radius
        row = s * np.sqrt(3.0) / 2.0
        best = np.zeros((0, 2))
        for across in (False, True):
            w, h = self.size[::-1] if across else self.size
            if w < 2 * r or h < 2 * r:
                continue
            j = np.arange(int((h - 2 * r) / row) + 2)
            i = np.arange(-1, int((w - 2 * r) / s) + 2)
            for fy in np.arange(4) / 4.0:
                for fx in np.arange(4) / 4.0:
                    y = r + (fy + j) * row
                    x = r + (fx + i[None, :] + 0.5 * (j[:, None] % 2)) * s
                    pts = np.stack([x, np.broadcast_to(y[:, None], x.shape)], -1).reshape(-1, 2)
                    pts = pts[(pts[:, 0] >= r) & (pts[:, 0] <= w - r) & (pts[:, 1] <= h - r)]
                    if across:
                        pts = pts[:, ::-1]
                    pts = pts[self._allowed(pts, max_cost)]
                    if len(pts) > len(best):
                        best = pts
        return best

    def _greedy_scan(self, s: float, max_cost: Optional[float], base: np.ndarray, across: bool) -> np.ndarray:
        """``base`` plus every allowed point of a grid of spacing ``s / 8`` that is at least ``s`` from
        the points taken before it, scanned row by row (column by column when ``across``)."""
        from scipy.spatial import cKDTree  # here: importing the package stays light

        r, d = self.agent_radius, s / 8.0
        w, h = self.size[::-1] if across else self.size
        xs = r + np.arange(int(np.floor((w - 2 * r) / d)) + 1) * d
        ys = r + np.arange(int(np.floor((h - 2 * r) / d)) + 1) * d
        allowed = self._allowed_grid(ys, xs).T if across else self._allowed_grid(xs, ys)
        if max_cost is not None or len(base):
            gx, gy = np.meshgrid(xs, ys)
            grid = np.stack([gy, gx] if across else [gx, gy], -1).reshape(-1, 2)[allowed.ravel()]  # world (x, y)
            keep = np.ones(len(grid), dtype=bool) if max_cost is None else self._allowed(grid, max_cost)
            if len(base):
                keep &= cKDTree(base).query(grid)[0] >= s
            allowed[allowed] = keep
        s2 = s * s
        taken = [base]
        recent = np.zeros((0, 2))  # taken by this scan in the rows less than s above (scan coordinates)
        for y, ok in zip(ys.tolist(), allowed):
            if not ok.any():
                recent = recent[recent[:, 1] > y - s]
                continue
            if len(recent):
                dx, dy = xs[ok][:, None] - recent[None, :, 0], y - recent[None, :, 1]
                ok = ok.copy()
                ok[ok] = (dx * dx + dy * dy).min(1) >= s2
            new, last = [], -np.inf
            for x in xs[ok].tolist():
                if x - last >= s:
                    new.append(x)
                    last = x
            recent = recent[recent[:, 1] > y - s]
            if new:
                pts = np.stack([np.array(new), np.full(len(new), y)], 1)
                recent = np.concatenate([recent, pts])
                taken.append(pts[:, ::-1] if across else pts)
        return np.concatenate(taken)

    def sample_separated(
        self, n: int, separation: float, rng: np.random.Generator, max_cost: Optional[float] = None,
        what: str = "position", rounds: int = 1000, separation_name: str = "separation",
    ) -> np.ndarray:
        """``n`` free positions at least ``separation`` apart, shape ``(n, 2)``; it succeeds for every
        ``n`` up to :meth:`capacity` and refuses more at once (``ValueError`` naming both).

        First all ``n`` are drawn uniformly at once and every round redraws the later position of
        each pair that is too close, for at most ``rounds`` rounds (skipped for counts beyond what
        random sampling can place, :meth:`max_agents` with :data:`RANDOM_FILL`). If that does not
        separate them, ``n`` positions of :meth:`packing` are drawn at random and then moved by 40
        rounds of random moves, each kept where it leaves the position allowed and ``separation``
        from the others (in a crowd near the capacity most positions cannot move). The result
        depends on the generator alone. ``what`` and ``separation_name`` name the positions and
        the separation in messages.
        """
        from scipy.spatial import cKDTree

        n = check_count(n, "n", 0)
        sep = float(separation)
        fit = self.capacity(sep, max_cost)
        if n > fit:
            cheap = "" if max_cost is None else f" with cost <= {max_cost:g}"
            raise ValueError(
                f"could not place {plural(n, what)} at least {separation_name}={sep:g} apart on {self.layout.name}: "
                f"its capacity is {fit}{cheap} at that separation; use at most {fit} or a smaller "
                f"{separation_name} (the least is 2 * agent_radius = {2.0 * self.agent_radius:g})"
            )
        if n <= max(self.max_agents(sep, RANDOM_FILL), 1):
            pts = self.sample_states(n, rng, max_cost=max_cost)
            sep2 = sep * sep
            reach = sep * (1.0 + 1e-9) + 1e-12  # candidate pairs; the exact test follows
            for _ in range(rounds):
                pairs = cKDTree(pts).query_pairs(reach, output_type="ndarray")
                if len(pairs):
                    d = pts[pairs[:, 0]] - pts[pairs[:, 1]]
                    pairs = pairs[(d * d).sum(-1) < sep2]
                if not len(pairs):
                    return pts
                redraw = np.unique(pairs.max(axis=1))
                pts[redraw] = self.sample_states(len(redraw), rng, max_cost=max_cost)
        return self._shuffled_packing(n, sep, rng, max_cost)

    def _shuffled_packing(self, n: int, sep: float, rng: np.random.Generator, max_cost: Optional[float],
                          moves: int = 40) -> np.ndarray:
        """``n`` random positions of :meth:`packing`, each then moved ``moves`` times at random
        (up to ``sep / 4`` per axis) where the move keeps it allowed and ``sep`` from the others."""
        from scipy.spatial import cKDTree

        slots = self.packing(sep, max_cost)
        pts = slots[rng.choice(len(slots), size=n, replace=False)]
        sep2 = sep * sep
        reach = sep * (1.0 + 1e-9) + 1e-12
        for _ in range(moves):
            prop = pts + rng.uniform(-0.25 * sep, 0.25 * sep, size=pts.shape)
            ok = self._allowed(prop, max_cost)
            # a move is refused when the new place is too close to another's old or new place
            pairs = cKDTree(np.concatenate([pts, prop])).query_pairs(reach, output_type="ndarray")
            if len(pairs):
                both = np.concatenate([pts, prop])
                d = both[pairs[:, 0]] - both[pairs[:, 1]]
                pairs = pairs[((d * d).sum(-1) < sep2) & (pairs[:, 0] % n != pairs[:, 1] % n)]
                moved = pairs[pairs >= n] - n  # the movers in a clash (indices n.. are new places)
                ok[moved] = False
            pts[ok] = prop[ok]
        return pts

    def check_agent_positions(self, points, n: int, what: str, overlap_ok: bool = False) -> np.ndarray:
        """Validate user-given starts or goals as an ``(n, 2)`` array: one free position per agent,
        no two overlapping (unless ``overlap_ok``: agents that pass through each other);
        ``ValueError`` naming the agent and the problem otherwise. ``what`` names the positions."""
        try:
            raw = np.asarray(points)
            if raw.dtype.kind == "c":
                raise TypeError("complex positions")
            p = raw.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"{what}s must be one real (x, y) pair per agent ({plural(n, 'agent')}), got {show(points)}"
            ) from exc
        if p.shape != (n, 2):
            raise ValueError(f"{what}s must be one (x, y) pair per agent: shape ({n}, 2), got shape {p.shape}")
        finite = np.isfinite(p).all(axis=1)
        ok = finite.copy()
        ok[finite] = self.is_free(p[finite])
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            self.check_position(p[i], f"{what} of agent_{i}")  # raises with the precise reason
        if overlap_ok:  # agents pass through each other: overlapping is fine
            return p
        close = self._first_overlap(p)
        if close is not None:
            i, j, dist = close
            raise ValueError(
                f"{what}s of agent_{i} and agent_{j} are {dist:.4g} apart, closer than "
                f"2 * agent_radius = {2.0 * self.agent_radius:g}: the agents would overlap"
            )
        return p

    def _first_overlap(self, p: np.ndarray) -> Optional[Tuple[int, int, float]]:
        """The first pair ``(i, j, distance)``, ``i < j`` in row-major order, of positions ``p``
        ``(n, 2)`` closer than ``2 * agent_radius``, or ``None``. Many positions are measured only
        in the pairs a k-d tree finds near each other (a little farther included, against
        rounding), with the same arithmetic as all pairs of a few."""
        from scipy.spatial import cKDTree

        limit = 2.0 * self.agent_radius
        if len(p) <= 256:
            diff = p[:, None] - p[None]
            dist = np.sqrt((diff * diff).sum(-1))
            close = np.argwhere(np.triu(dist < limit, k=1))
            if not len(close):
                return None
            i, j = (int(k) for k in close[0])
            return i, j, float(dist[i, j])
        pairs = cKDTree(p).query_pairs(limit * (1.0 + 1e-9) + 1e-12, output_type="ndarray")
        if not len(pairs):
            return None
        diff = p[pairs[:, 0]] - p[pairs[:, 1]]
        dist = np.sqrt((diff * diff).sum(-1))
        keep = dist < limit
        if not keep.any():
            return None
        pairs, dist = pairs[keep], dist[keep]
        first = int(np.lexsort((pairs[:, 1], pairs[:, 0]))[0])
        return int(pairs[first, 0]), int(pairs[first, 1]), float(dist[first])

    def sample_goals_in_band(self, starts: np.ndarray, band: Tuple[float, float], min_separation: float,
                             rng: np.random.Generator) -> np.ndarray:
        """One goal per start at a geodesic distance from it within ``band``, the goals at least
        ``min_separation`` apart.

        Each goal needs a geodesic query from its own start, hence one draw per agent; a draw
        too close to an earlier agent's goal is repeated.
        """
        sep = float(min_separation)
        fit = self.capacity(sep)
        if len(starts) > fit:
            raise ValueError(
                f"could not place {plural(len(starts), 'goal')} at least min_separation={sep:g} apart on "
                f"{self.layout.name}: its capacity is {fit} at that separation; use fewer agents or a smaller "
                "min_separation"
            )
        goals = np.empty_like(starts)
        for i, start in enumerate(starts):
            for _ in range(100):
                g = self.sample_goal_in_band(start, band, rng)
                if i == 0 or np.min(np.hypot(*(goals[:i] - g).T)) >= sep:
                    goals[i] = g
                    break
            else:
                raise ValueError(
                    f"could not place the goal of agent_{i} in the goal_distance band {show(tuple(band))} at least "
                    f"min_separation={sep:g} from the other goals; use fewer agents or a wider band"
                )
        return goals


__all__ = ["Layout", "NavigationScenario", "RANDOM_FILL", "resolve_layout", "union_area"]
