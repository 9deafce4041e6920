"""Single-agent search on a :class:`~agents.search.graph.build.WaypointGraph`.

Three objectives:

- ``"distance"``: shortest path by predicted distance (Search on the Replay Buffer; with a
  cost-pruned graph this is the constrained search of the paper "Safe Multi-Agent Navigation
  guided by Goal-Conditioned Safe Reinforcement Learning");
- ``"weighted"``: shortest path by ``D + beta * C``, to trade speed for safety;
- :func:`risk_bounded_path`: the shortest path whose total predicted cost stays within a
  budget (a resource-constrained shortest path), or a clear ``infeasible`` answer. The paper
  names the lack of such a bound as its limitation.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import List

import numpy as np
from scipy.sparse.csgraph import dijkstra

from .build import WaypointGraph
from .pruning import route_from_predecessors


@dataclass
class Plan:
    """A single-agent plan: node ids from start to goal and its predicted totals."""

    nodes: List[int]
    distance: float
    cost: float
    status: str  # "optimal" | "feasible" (within budget, maybe not shortest) | "infeasible" | "limit"
    stats: dict = field(default_factory=dict)

    @property
    def found(self) -> bool:
        return self.status in ("optimal", "feasible")

    @property
    def waypoints(self) -> List[int]:
        """The intermediate nodes (start and goal excluded)."""
        return self.nodes[1:-1]


def _path_totals(graph: WaypointGraph, nodes: List[int]) -> tuple:
    if len(nodes) < 2:
        return 0.0, 0.0
    a, b = np.array(nodes[:-1]), np.array(nodes[1:])
    d = np.asarray(graph.distance[a, b]).ravel().sum()
    c = np.asarray(graph.cost[a, b]).ravel().sum()
    return float(d), float(c)


def _check_node(graph: WaypointGraph, node: int, what: str) -> int:
    node = int(node)
    if not 0 <= node < graph.n_nodes:
        raise ValueError(f"{what} node {node} is not in the graph (it has {graph.n_nodes} nodes)")
    return node


def shortest_path(
    graph: WaypointGraph,
    source: int,
    target: int,
    objective: str = "distance",
    beta: float = 1.0,
) -> Plan:
    """Shortest path from ``source`` to ``target``.

    Args:
        objective: ``"distance"`` (edge weight ``D``), ``"cost"`` (``C``) or ``"weighted"``
            (``D + beta * C``).
        beta: safety weight of the ``"weighted"`` objective (>= 0).

    Returns:
        A :class:`Plan`; ``status="infeasible"`` with no nodes when the target is unreachable.
    """
    source = _check_node(graph, source, "source")
    target = _check_node(graph, target, "target")
    w = graph.weight_matrix(objective, beta)
    dist, pred = dijkstra(w, directed=True, indices=source, return_predecessors=True)
    if not np.isfinite(dist[target]):
        return Plan([], np.inf, np.inf, "infeasible")
    nodes = route_from_predecessors(pred, source, target)
    d, c = _path_totals(graph, nodes)
    return Plan(nodes, d, c, "optimal", {"objective": objective})


def risk_bounded_path(
    graph: WaypointGraph,
    source: int,
    target: int,
    budget: float,
    max_labels: int = 2_000_000,
) -> Plan:
    """The shortest path (by predicted distance) whose total predicted cost is at most ``budget``.

    Exact label-setting search over (distance, cost) labels with Pareto-dominance pruning
    and admissible bounds (the cheapest remaining cost and the shortest remaining distance,
    from reverse Dijkstra), so only labels that can still meet the budget and beat the best
    path found are expanded.

    Returns:
        ``status="optimal"`` with the path; ``"infeasible"`` when no path meets the budget
        (or the target is unreachable); ``"limit"`` if ``max_labels`` labels were expanded
        first (then the best path found so far, if any, is returned).
    """
    source = _check_node(graph, source, "source")
    target = _check_node(graph, target, "target")
    if not budget >= 0:
        raise ValueError(f"budget must be >= 0, got {budget!r}")
    D = graph.distance.tocsr()
    Cw = D.copy()
    Cw.data = graph.cost_data()
    # bounds to the target on the reversed graph
    h_d = dijkstra(D.T.tocsr(), directed=True, indices=target)
    h_c = dijkstra(Cw.T.tocsr(), directed=True, indices=target)
    if not np.isfinite(h_d[source]):
        return Plan([], np.inf, np.inf, "infeasible", {"reason": "target unreachable"})
    if h_c[source] > budget:
        return Plan([], np.inf, np.inf, "infeasible",
                    {"reason": f"cheapest path costs {h_c[source]:.3f} > budget {budget:g}"})
    indptr, indices, dvals, cvals = D.indptr, D.indices, D.data, Cw.data
    # labels: parallel lists (distance, cost, node, parent label)
    L_d: List[float] = [0.0]
    L_c: List[float] = [0.0]
    L_n: List[int] = [source]
    L_p: List[int] = [-1]
    front: List[List[tuple]] = [[] for _ in range(graph.n_nodes)]  # Pareto front per node: (d, c)
    front[source].append((0.0, 0.0))
    heap = [(h_d[source], 0.0, 0)]
    best_d, best_label = np.inf, -1
    expanded = 0
    status = "optimal"
    while heap:
        f, _, lab = heapq.heappop(heap)
        if f >= best_d:
            break
        d, c, u = L_d[lab], L_c[lab], L_n[lab]
        if (d, c) not in front[u]:  # dominated after it was queued
            continue
        expanded += 1
        if expanded > max_labels:
            status = "limit"
            break
        if u == target:
            best_d, best_label = d, lab
            break  # labels pop in order of d + h_d with an admissible h_d: the first is best
        for k in range(indptr[u], indptr[u + 1]):
            v = int(indices[k])
            nd, nc = d + dvals[k], c + cvals[k]
            if nc + h_c[v] > budget or nd + h_d[v] >= best_d:
                continue
            fr = front[v]
            if any(fd <= nd and fc <= nc for fd, fc in fr):
                continue
            front[v] = [(fd, fc) for fd, fc in fr if not (nd <= fd and nc <= fc)]
            front[v].append((nd, nc))
            L_d.append(nd)
            L_c.append(nc)
            L_n.append(v)
            L_p.append(lab)
            heapq.heappush(heap, (nd + h_d[v], nc, len(L_d) - 1))
    stats = {"labels_expanded": expanded, "labels_created": len(L_d), "budget": budget}
    if best_label < 0:
        return Plan([], np.inf, np.inf, "infeasible" if status == "optimal" else status, stats)
    nodes = []
    lab = best_label
    while lab >= 0:
        nodes.append(L_n[lab])
        lab = L_p[lab]
    nodes.reverse()
    return Plan(nodes, L_d[best_label], L_c[best_label], status, stats)


def lagrangian_risk_path(
    graph: WaypointGraph,
    source: int,
    target: int,
    budget: float,
    max_iter: int = 30,
) -> Plan:
    """A short path whose total predicted cost is at most ``budget``, by Lagrangian relaxation.

    The LARAC scheme: shortest paths under ``D + lam * C``, with ``lam`` set from the best
    path known to meet the budget and the best one known to break it, until they agree. A few
    Dijkstra calls instead of a label search: the result always meets the budget (when any
    path does) but may be longer than :func:`risk_bounded_path`'s optimum; ``stats["gap"]``
    bounds how much longer (the Lagrangian lower bound).
    """
    source = _check_node(graph, source, "source")
    target = _check_node(graph, target, "target")
    if not budget >= 0:
        raise ValueError(f"budget must be >= 0, got {budget!r}")
    fast = shortest_path(graph, source, target, "distance")
    if not fast.found:
        return Plan([], np.inf, np.inf, "infeasible", {"reason": "target unreachable"})
    if fast.cost <= budget:
        return Plan(fast.nodes, fast.distance, fast.cost, "optimal", {"iterations": 0})
    safe = shortest_path(graph, source, target, "cost")
    if safe.cost > budget:
        return Plan([], np.inf, np.inf, "infeasible",
                    {"reason": f"cheapest path costs {safe.cost:.3f} > budget {budget:g}"})
    lower = fast.distance
    iterations = 0
    while iterations < max_iter:
        iterations += 1
        if fast.cost - safe.cost <= 1e-12:
            break
        lam = (safe.distance - fast.distance) / (fast.cost - safe.cost)
        r = shortest_path(graph, source, target, "weighted", beta=lam)
        lower = max(lower, r.distance + lam * (r.cost - budget))
        w_r = r.distance + lam * r.cost
        if w_r >= safe.distance + lam * safe.cost - 1e-9:
            break
        if r.cost <= budget:
            safe = r
        else:
            fast = r
    return Plan(safe.nodes, safe.distance, safe.cost, "feasible",
                {"iterations": iterations, "gap": safe.distance - lower})


__all__ = ["Plan", "lagrangian_risk_path", "risk_bounded_path", "shortest_path"]
