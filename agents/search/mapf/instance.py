"""A multi-agent path finding instance on a directed graph, normalised for the CBS solver.

The graph may come as a scipy sparse matrix of edge durations, a dense matrix, or an adjacency
list; it is turned into integer successor lists and a CSR matrix once. Each agent gets a
true-distance heuristic (reverse Dijkstra from its goal, with ``scipy.sparse.csgraph``).
Proximity (a node-distance function and a radius) is turned into per-node "near" lists.

Numpy/scipy only; the solver never sees observations or critics, only numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

#: Heuristic value of a node from which the goal cannot be reached.
UNREACHABLE = 1 << 40

TIME_MODELS = ("unit", "durative")

GraphLike = Union[sparse.spmatrix, "sparse.sparray", np.ndarray, Sequence, Mapping]


@dataclass(frozen=True)
class Proximity:
    """Agents at distinct nodes ``u != v`` conflict when they are closer than ``radius``.

    ``node_dist`` is a dense ``(N, N)`` matrix or a callable ``node_dist(u, v) -> float`` (it
    is evaluated once for every ordered pair, so prefer a matrix on large graphs). The
    distance may be asymmetric (e.g. a learned critic); two nodes are *near* when either
    direction is below the radius. ``exempt`` lists ranges ``(lo, hi)`` of nodes ``lo .. hi - 1``
    that are never near one another (e.g. agents' starts that the environment places side by side),
    whatever their distance.
    """

    node_dist: Union[np.ndarray, Callable[[int, int], float]]
    radius: float
    exempt: Tuple[Tuple[int, int], ...] = ()

    def near_matrix(self, n_nodes: int) -> np.ndarray:
        """Boolean ``(N, N)`` matrix, symmetric, False on the diagonal: which node pairs are near."""
        if not (isinstance(self.radius, (int, float, np.floating, np.integer)) and self.radius >= 0):
            raise ValueError(f"proximity radius must be a non-negative number, got {self.radius!r}")
        if callable(self.node_dist):
            d = np.empty((n_nodes, n_nodes), dtype=np.float64)
            for u in range(n_nodes):
                for v in range(n_nodes):
                    d[u, v] = float(self.node_dist(u, v))
        else:
            d = np.asarray(self.node_dist, dtype=np.float64)
            if d.shape != (n_nodes, n_nodes):
                raise ValueError(f"proximity node_dist must have shape ({n_nodes}, {n_nodes}), got {d.shape}")
        if np.isnan(d).any():
            raise ValueError("proximity node_dist contains NaN")
        near = d < self.radius
        rows, cols = np.nonzero(near)
        near[cols, rows] = True  # either direction (few pairs: no pass over the transposed matrix)
        np.fill_diagonal(near, False)
        for lo, hi in self.exempt:
            near[lo:hi, lo:hi] = False
        return near


#: What ``proximity`` arguments accept: ``None``, a :class:`Proximity` or ``(node_dist, radius)``.
ProximityLike = Union[None, Proximity, Tuple[Any, float]]


def as_proximity(proximity: ProximityLike) -> Optional[Proximity]:
    """Accept ``None``, a :class:`Proximity` or a ``(node_dist, radius)`` pair."""
    if proximity is None or isinstance(proximity, Proximity):
        return proximity
    if isinstance(proximity, tuple) and len(proximity) == 2:
        return Proximity(proximity[0], float(proximity[1]))
    raise ValueError(f"proximity must be a Proximity or a (node_dist, radius) pair, got {type(proximity).__name__}")


def integer_durations(distances: Union[sparse.spmatrix, np.ndarray], minimum: int = 1) -> sparse.csr_matrix:
    """Round a matrix of predicted edge distances up to integer step counts (at least ``minimum``).

    Stored (sparse) or positive finite (dense) entries are edges; the result is a CSR matrix
    usable as the ``graph`` of the durative time model, where an edge takes as many plan steps
    as it is predicted to take environment steps.
    """
    if sparse.issparse(distances):
        m = sparse.csr_matrix(distances, dtype=np.float64, copy=True)
        m.eliminate_zeros()
    else:
        d = np.asarray(distances, dtype=np.float64)
        keep = np.isfinite(d) & (d > 0)
        r, c = np.nonzero(keep)
        m = sparse.csr_matrix((d[r, c], (r, c)), shape=d.shape)
    if (m.data < 0).any() or np.isnan(m.data).any():
        raise ValueError("distances must be non-negative and not NaN")
    m.data = np.maximum(np.ceil(m.data - 1e-9), minimum)
    return m


def edges_from_graph(graph: GraphLike) -> Tuple[int, Dict[Tuple[int, int], float]]:
    """Number of nodes and ``{(u, v): duration}`` (self-loops dropped, parallel edges -> min)."""
    edges: Dict[Tuple[int, int], float] = {}

    def put(u: int, v: int, d: float) -> None:
        if u == v:
            return
        old = edges.get((u, v))
        if old is None or d < old:
            edges[(u, v)] = d

    if sparse.issparse(graph) or isinstance(graph, np.ndarray):
        n_mat, r_arr, c_arr, d_arr = edge_arrays(graph)
        return n_mat, dict(zip(zip(r_arr.tolist(), c_arr.tolist()), d_arr.tolist()))
    if isinstance(graph, Mapping):
        keys = list(graph.keys())
        if not all(isinstance(k, (int, np.integer)) and k >= 0 for k in keys):
            raise ValueError("an adjacency mapping must have non-negative integer node ids as keys")
        n = (max(keys) + 1) if keys else 0
        rows = [graph.get(u, ()) for u in range(n)]
    elif isinstance(graph, Sequence) and not isinstance(graph, (str, bytes)):
        rows = list(graph)
        n = len(rows)
    else:
        raise ValueError(
            f"unsupported graph type {type(graph).__name__}: use a sparse/dense matrix or an adjacency list")
    parsed: List[Tuple[int, int, float]] = []
    for u, row in enumerate(rows):
        for item in row:
            if isinstance(item, (tuple, list)):
                if len(item) != 2:
                    raise ValueError(f"adjacency entry {item!r} of node {u} must be v or (v, duration)")
                v, d = item
            else:
                v, d = item, 1
            if not isinstance(v, (int, np.integer)):
                raise ValueError(f"adjacency entry {item!r} of node {u}: node ids must be integers")
            d = float(d)
            if not d > 0 or math.isnan(d):
                raise ValueError(f"edge {u}->{v} has a non-positive duration {d:g}")
            parsed.append((u, int(v), d))
            n = max(n, int(v) + 1)
    for u, v, d in parsed:
        if v < 0:
            raise ValueError(f"edge {u}->{v}: negative node id")
        put(u, v, d)
    return n, edges


def edge_arrays(graph: GraphLike) -> Tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`edges_from_graph` as arrays ``(n, rows, cols, durations)`` sorted by ``(row, col)``.

    Matrices (sparse or dense) are converted without a Python loop over their edges (a
    1000-node buffer graph has 10^5 of them); adjacency lists go through :func:`edges_from_graph`.
    """
    if not (sparse.issparse(graph) or isinstance(graph, np.ndarray)):
        n_adj, edges = edges_from_graph(graph)
        keys = sorted(edges)
        rows = np.fromiter((u for u, _ in keys), dtype=np.int64, count=len(keys))
        cols = np.fromiter((v for _, v in keys), dtype=np.int64, count=len(keys))
        durs = np.fromiter((edges[k] for k in keys), dtype=np.float64, count=len(keys))
        return n_adj, rows, cols, durs
    if sparse.issparse(graph):
        m = sparse.coo_matrix(graph)
        if m.shape[0] != m.shape[1]:
            raise ValueError(f"graph matrix must be square, got shape {m.shape}")
        n = int(m.shape[0])
        r, c, d = m.row.astype(np.int64), m.col.astype(np.int64), np.asarray(m.data, dtype=np.float64)
        if np.isnan(d).any():
            raise ValueError("graph matrix contains NaN durations")
        if (d < 0).any():
            raise ValueError(f"graph matrix contains a negative duration ({d.min():g})")
        keep = (d != 0) & np.isfinite(d)
    else:
        arr = np.asarray(graph)
        if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
            raise ValueError(f"graph matrix must be square 2-D, got shape {arr.shape}")
        n = int(arr.shape[0])
        dense = arr.astype(np.float64)
        if np.isnan(dense).any():
            raise ValueError("graph matrix contains NaN durations")
        if (dense < 0).any():
            raise ValueError(f"graph matrix contains a negative duration ({dense.min():g})")
        r, c = np.nonzero(np.isfinite(dense) & (dense > 0))
        r, c, d = r.astype(np.int64), c.astype(np.int64), dense[r, c]
        keep = np.ones(len(d), dtype=bool)
    keep &= r != c  # self-loops dropped: waiting is always allowed
    r, c, d = r[keep], c[keep], d[keep]
    order = np.lexsort((d, c, r))  # by row, column, then the shortest parallel edge first
    r, c, d = r[order], c[order], d[order]
    first = np.ones(len(r), dtype=bool)
    first[1:] = (r[1:] != r[:-1]) | (c[1:] != c[:-1])
    return n, r[first], c[first], d[first]


class MapfInstance:
    """A normalised instance: graph, starts, goals, time model, proximity, heuristics.

    Args:
        graph: edge durations as a scipy sparse matrix (stored non-zero entries are edges), a
            dense matrix (positive finite entries are edges), or an adjacency list
            ``adj[u] = [v, ...]`` / ``[(v, duration), ...]`` (or a mapping ``u -> ...``).
            Self-loops are dropped: waiting in place is always allowed and takes one step.
        starts, goals: one node id per agent; starts must be distinct, goals must be distinct.
        time_model: ``"unit"`` (every move takes one step, durations ignored) or ``"durative"``
            (a move takes its integer duration in steps; durations must be integers >= 1).
        proximity: optional :class:`Proximity` (or ``(node_dist, radius)``).

    Raises:
        ValueError: on a bad graph, node id, duplicate start/goal or bad duration.
    """

    def __init__(
        self,
        graph: GraphLike,
        starts: Sequence[int],
        goals: Sequence[int],
        *,
        time_model: str = "unit",
        proximity: ProximityLike = None,
    ):
        if time_model not in TIME_MODELS:
            raise ValueError(f"time_model must be one of {TIME_MODELS}, got {time_model!r}")
        self.time_model = time_model
        self.unit = time_model == "unit"
        n, rows, cols, durs = edge_arrays(graph)
        self.n_nodes = n
        starts = [self._node(s, "start", i, n) for i, s in enumerate(starts)]
        goals = [self._node(g, "goal", i, n) for i, g in enumerate(goals)]
        if len(starts) != len(goals):
            raise ValueError(f"{len(starts)} starts but {len(goals)} goals")
        for what, nodes in (("start", starts), ("goal", goals)):
            seen: Dict[int, int] = {}
            for i, v in enumerate(nodes):
                if v in seen:
                    raise ValueError(f"agents {seen[v]} and {i} share the {what} node {v}")
                seen[v] = i
        self.starts: Tuple[int, ...] = tuple(starts)
        self.goals: Tuple[int, ...] = tuple(goals)
        self.n_agents = len(starts)

        if self.unit:
            durs = np.ones_like(durs)
        else:
            bad = np.nonzero((durs != np.round(durs)) | (durs < 1))[0]
            if len(bad):
                k = int(bad[0])
                raise ValueError(
                    f"durative time model needs integer durations >= 1; edge {rows[k]}->{cols[k]} has {durs[k]:g} "
                    "(see integer_durations)")
        #: CSR matrix of the durations used for planning (all ones under unit time).
        self.durations = sparse.csr_matrix((durs, (rows, cols)), shape=(n, n))
        dint = durs.astype(np.int64)
        bounds = np.searchsorted(rows, np.arange(n + 1)).tolist()
        col_list, dur_list = cols.tolist(), dint.tolist()
        succ: List[List[int]] = [[v] + col_list[bounds[v]:bounds[v + 1]] for v in range(n)]  # waiting comes first
        succ_d: List[List[Tuple[int, int]]] = [
            [(v, 1)] + list(zip(col_list[bounds[v]:bounds[v + 1]], dur_list[bounds[v]:bounds[v + 1]]))
            for v in range(n)]
        #: successor lists (wait included first) for unit time.
        self.succ = succ
        #: successor lists ``(v, duration)`` (wait ``(u, 1)`` included first).
        self.succ_d = succ_d
        self.max_duration = int(dint.max()) if len(dint) else 1

        self.proximity = as_proximity(proximity)
        if self.proximity is not None:
            near = self.proximity.near_matrix(n)
            self.near_mat: Optional[np.ndarray] = near
            rows_near, cols_near = np.nonzero(near)  # row by row, columns ascending
            cut = np.searchsorted(rows_near, np.arange(n + 1)).tolist()
            flat_near = cols_near.tolist()
            self.near: Optional[List[List[int]]] = [flat_near[cut[u]:cut[u + 1]] for u in range(n)]
            if not any(self.near):
                self.near = None  # nothing is ever near: plain vertex semantics
        else:
            self.near_mat = None
            self.near = None

        # true-distance heuristics (reverse Dijkstra from each goal)
        if self.n_agents:
            dist = dijkstra(self.durations.T.tocsr(), directed=True, indices=list(self.goals), unweighted=self.unit)
            dist = np.atleast_2d(dist)
            self.h_array = np.where(np.isfinite(dist), dist, UNREACHABLE).astype(np.int64)
        else:
            self.h_array = np.zeros((0, n), dtype=np.int64)
        self._h: Optional[List[List[int]]] = None
        self._pred: Optional[List[List[int]]] = None
        self._must_pass: Dict[Tuple[int, int], frozenset] = {}
        self._dist_to: Dict[Tuple[int, frozenset], List[int]] = {}
        #: per agent, the successors of every node from which its goal is reachable, with their
        #: distances (filled in by :func:`agents.search.mapf.successors.goal_successors`)
        self._goal_successors: Dict[int, List[List[Tuple[int, int]]]] = {}
        self._moves_csr: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None

    # ------------------------------------------------------------------ graph helpers
    @property
    def h(self) -> List[List[int]]:
        """Per agent, the true distance (in steps) from every node to its goal (:attr:`h_array` as
        lists, made on first use: the Python searches index them fastest)."""
        if self._h is None:
            self._h = [row.tolist() for row in self.h_array]
        return self._h

    @property
    def pred(self) -> List[List[int]]:
        """Predecessor lists (waits excluded)."""
        if self._pred is None:
            pred: List[List[int]] = [[] for _ in range(self.n_nodes)]
            for u in range(self.n_nodes):
                for v in self.succ[u][1:]:
                    pred[v].append(u)
            self._pred = pred
        return self._pred

    @property
    def moves_csr(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The moves (waits excluded) as CSR arrays ``(indptr, targets, durations)``, in the order
        of :attr:`succ_d` (for the compiled loops of :mod:`~agents.search.mapf.compiled`)."""
        if self._moves_csr is None:
            rows = [row[1:] for row in self.succ_d]
            indptr = np.zeros(len(rows) + 1, dtype=np.int64)
            np.cumsum([len(r) for r in rows], out=indptr[1:])
            flat = [e for r in rows for e in r]
            targets = np.array([v for v, _ in flat], dtype=np.int64)
            durations = np.array([d for _, d in flat], dtype=np.int64)
            self._moves_csr = (indptr, targets, durations)
        return self._moves_csr

    def dist_to(self, target: int, blocked: frozenset = frozenset()) -> List[int]:
        """Steps from every node to ``target`` (unit time), avoiding ``blocked`` nodes (cached)."""
        key = (target, blocked)
        d = self._dist_to.get(key)
        if d is None:
            d = [UNREACHABLE] * self.n_nodes
            d[target] = 0
            frontier = [target]
            pred = self.pred
            step = 0
            while frontier:
                step += 1
                nxt = []
                for v in frontier:
                    for u in pred[v]:
                        if d[u] == UNREACHABLE and u not in blocked:
                            d[u] = step
                            nxt.append(u)
                frontier = nxt
            if len(self._dist_to) > 20_000:
                self._dist_to.clear()
            self._dist_to[key] = d
        return d

    def must_pass(self, goal: int, node: int) -> frozenset:
        """Nodes (other than ``node``) from which every path to ``goal`` goes through ``node`` (cached)."""
        key = (goal, node)
        m = self._must_pass.get(key)
        if m is None:
            if node == goal:
                m = frozenset()
            else:
                free = self.dist_to(goal, frozenset((node,)))
                full = self.dist_to(goal)
                m = frozenset(v for v in range(self.n_nodes)
                              if free[v] >= UNREACHABLE and full[v] < UNREACHABLE and v != node)
            self._must_pass[key] = m
        return m

    @staticmethod
    def _node(v: Any, what: str, i: int, n: int) -> int:
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool):
            raise ValueError(f"{what} of agent {i} must be an integer node id, got {v!r}")
        v = int(v)
        if not 0 <= v < n:
            raise ValueError(f"{what} of agent {i} is node {v}, not in the graph (it has {n} nodes)")
        return v

    # ------------------------------------------------------------------ quick facts
    def unreachable_agents(self) -> List[int]:
        """Agents whose goal cannot be reached from their start."""
        return [i for i in range(self.n_agents) if self.h_array[i, self.starts[i]] >= UNREACHABLE]

    def is_near(self, u: int, v: int) -> bool:
        """Whether agents at ``u != v`` would be in proximity conflict."""
        return self.near_mat is not None and u != v and bool(self.near_mat[u, v])

    def duration(self, u: int, v: int) -> Optional[int]:
        """Steps a move ``u -> v`` takes (1 for a wait ``u == v``), ``None`` if there is no edge."""
        if u == v:
            return 1
        for w, d in self.succ_d[u]:
            if w == v:
                return 1 if self.unit else d
        return None
