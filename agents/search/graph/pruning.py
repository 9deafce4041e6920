"""What the cost cut-off of a problem graph may give back (the layout of
:class:`~agents.search.graph.build.ProblemGraph`: buffer nodes, then the agents' starts, then their goals).

- :func:`relax_cost_locally`: an agent that the cut-off leaves without a path gets the edges
  around its start and goal back, at a doubling cut-off, until it has one;
- :func:`admit_cheaper_routes`: an agent that the cut-off sends the long way round, at a far
  higher predicted cost, gets its plain shortest route back where :func:`trusted_edges` trusts it;
- :func:`long_legs`: the edges a second critic (the driver's) reads as too long to drive, which
  neither the cut-off nor its relaxation may admit.
"""
from __future__ import annotations

import math
from typing import Callable, List, Optional, Tuple

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from .edges import EdgeList

#: ``confirm(u, v) -> distances``: a second critic's predicted steps along the edges ``u[i] -> v[i]`` (node ids)
ConfirmFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def read_pairs(read: ConfirmFn, observations: np.ndarray, pairs: np.ndarray, batch: int = 4096) -> np.ndarray:
    """``read(observations[u], observations[v])`` for each node pair ``(u, v)`` of ``pairs`` (``(E, 2)``)."""
    out = [np.asarray(read(observations[pairs[s:s + batch, 0]], observations[pairs[s:s + batch, 1]]),
                      dtype=np.float64).reshape(-1) for s in range(0, len(pairs), batch)]
    return np.concatenate(out) if out else np.zeros(0)


def long_legs(edges: EdgeList, observations: np.ndarray, n_buffer: int, read: ConfirmFn, max_leg: float,
              buffer_long: Optional[np.ndarray] = None) -> np.ndarray:
    """The edges of ``edges`` (a problem's :func:`~agents.search.graph.edges.problem_edges`, or a buffer's
    short edges) that ``read`` (a second critic: the driver's) puts beyond ``max_leg`` steps, as
    ``(E, 2)`` node pairs.

    A driver that reads a leg that long hands it to its fallback policy at once (the controller's
    ``fallback_beyond``), so a plan that holds it drives it the costly way. ``buffer_long``: those
    between buffer nodes, where the caller has them (they are read once per graph: about 8 s for
    Apartment3's 61,245 edges on one core); then only the edges of the starts and goals are read.
    """
    ask = None if buffer_long is None else ~((edges.u < n_buffer) & (edges.v < n_buffer))
    pairs = edges.pairs(ask)
    found = pairs[read_pairs(read, observations, pairs) > max_leg]
    if buffer_long is None:
        return found.astype(np.int64)
    return np.concatenate([np.asarray(buffer_long, dtype=np.int64).reshape(-1, 2), found]).astype(np.int64)


def admissible(edges: EdgeList, exclude: Optional[np.ndarray] = None,
               exclude_edges: Optional[np.ndarray] = None) -> np.ndarray:
    """Which of a problem's candidate ``edges`` (:func:`~agents.search.graph.edges.problem_edges`: every
    edge it may hold whatever the cost cut-off) are allowed: none at ``exclude`` (buffer nodes) and none
    of ``exclude_edges`` (``(E, 2)`` node pairs). A boolean array over the edges."""
    ok = np.ones(len(edges), bool)
    if exclude is not None and len(exclude):
        bad = np.zeros(edges.n_nodes, bool)
        bad[np.asarray(exclude, np.int64)] = True
        ok &= ~bad[edges.u] & ~bad[edges.v]
    if exclude_edges is not None and len(exclude_edges):
        ee = np.asarray(exclude_edges, np.int64).reshape(-1, 2)
        at = edges.find(ee[:, 0], ee[:, 1])
        ok[at[at >= 0]] = False
    return ok


def route_from_predecessors(pred: np.ndarray, source: int, target: int) -> List[int]:
    """The nodes from ``source`` to ``target`` along a shortest-path tree (``pred``: Dijkstra's
    predecessors from ``source``; ``target`` must be reachable)."""
    nodes = [int(target)]
    while nodes[-1] != source:
        nodes.append(int(pred[nodes[-1]]))
    return nodes[::-1]


def shortest_routes(edges: EdgeList, mask: Optional[np.ndarray], sources: np.ndarray,
                    targets: np.ndarray) -> List[Optional[List[int]]]:
    """The shortest route (by predicted distance, over the ``edges`` where ``mask`` holds; ``None``: all) from each of
    ``sources`` to the target beside it, as node ids from source to target; ``None`` where there is none."""
    dist, pred = dijkstra(edges.matrix(mask), directed=True, indices=sources, return_predecessors=True)
    out: List[Optional[List[int]]] = []
    for i, t in enumerate(targets):
        if not np.isfinite(dist[i, t]):
            out.append(None)
            continue
        out.append(route_from_predecessors(pred[i], int(sources[i]), int(t)))
    return out


def trusted_edges(route: List[int], D: np.ndarray, C: np.ndarray, hops: sparse.csr_matrix, d_max: float,
                  corroboration: float = 2.0, cost_rate: float = 2.0,
                  confirm: Optional[ConfirmFn] = None) -> np.ndarray:
    """Which edges ``u -> v`` of ``route`` read as real rather than as a wormhole (two panoramas
    alike, far apart: a hop the critic predicts at a few steps that is some 60 m long).

    An edge is trusted unless either test flags it:

    - its predicted cost is more than its predicted steps can make it, ``C[u, v] > cost_rate *
      (D[u, v] + 1)`` (one step costs at most 1; 6 of the 9 wormholes measured on Apartment2's
      graph read 4-9 per predicted step, real edges 1 in the median and under 1.6 in 90%);
    - no chain of hops shorter than ``d_max / 2`` (``hops``) leads from ``u`` to ``v`` within
      ``corroboration`` times ``D[u, v]``, and the reverse reading ``D[v, u]`` is more than
      ``1.5 * d_max``. A real edge out of a corner with few nodes near (an agent's start, say)
      has no chain but reads short both ways; the wormholes that the cost reading misses read
      about 20 steps backwards. With ``confirm`` (a second critic, trained apart: the driving agent's),
      such an edge is still trusted where that critic reads it within ``1.5 * d_max`` too. Two critics
      rarely mistake the same pair of panoramas for neighbours: on Apartment2's and Apartment3's
      graphs the driving agents read 16 of 17 wormholes measured at 19-20 steps (the 17th fails the
      cost test), and 79-91% of the real edges that read long backwards within ``1.5 * d_max`` (a
      narrow passage with no node inside has no chain and reads so).
    """
    u, v = np.asarray(route[:-1]), np.asarray(route[1:])
    forward = D[u, v]
    chain = dijkstra(hops, directed=True, indices=u)[np.arange(len(u)), v]
    cheap = C[u, v] <= cost_rate * (forward + 1.0)
    corroborated = (chain <= corroboration * forward) | (D[v, u] <= 1.5 * d_max)
    ask = cheap & ~corroborated
    if confirm is not None and ask.any():
        corroborated[ask] = np.asarray(confirm(u[ask], v[ask]), dtype=np.float64).reshape(-1) <= 1.5 * d_max
    return cheap & corroborated


def admit_cheaper_routes(keep: np.ndarray, edges: EdgeList, D: np.ndarray, C: np.ndarray, n_buffer: int,
                         d_max: float, allowed: Optional[np.ndarray] = None, factor: float = 2.0,
                         corroboration: float = 2.0, detour: Optional[float] = None,
                         confirm: Optional[ConfirmFn] = None) -> np.ndarray:
    """Admit (edit ``keep``, a mask over the problem's candidate ``edges``) each agent's shortest route
    over every ``allowed`` edge (:func:`admissible`; default: all) where the cost cut-off made its
    shortest route more than ``factor`` times as costly by the critic, or (``detour``, ``None``: off)
    more than that many times as long and costlier at all.

    Pruning costly edges is meant to lower an agent's cost; a cut-off that leaves only a long
    detour of cheap edges can make the route's predicted cost (the sum of ``C`` over its edges)
    several times that of the plain shortest route (a traced Apartment0 plan: 16 hops, predicted
    35, against one hop, predicted 11, and 31 against 6 when driven). A small excess is worth
    paying: the cut-off also keeps out edges the critic misjudges (a hop through a wall reads
    costly), and short hops are driven more reliably. A detour that is both longer and costlier
    buys nothing. The plain route is admitted only where :func:`trusted_edges` trusts every edge
    of it (``corroboration``: its chain factor; ``confirm``: its second critic; ``D`` and ``C``: the
    problem's matrices, read along routes). Returns which agents got their plain shortest route
    admitted.
    """
    n = n_buffer
    k = (edges.n_nodes - n) // 2
    s_ids, g_ids = np.arange(n, n + k), np.arange(n + k, n + 2 * k)
    admitted = np.zeros(k, dtype=bool)
    if allowed is None:
        allowed = np.ones(len(edges), bool)
    plain = shortest_routes(edges, allowed, s_ids, g_ids)
    pruned = shortest_routes(edges, keep, s_ids, g_ids)
    hops = None

    def totals(route: List[int]) -> Tuple[float, float]:  # (length, cost) by the critic
        return float(D[route[:-1], route[1:]].sum()), float(C[route[:-1], route[1:]].sum())

    for i, (p, q) in enumerate(zip(plain, pruned)):
        if p is None or q is None:
            continue
        (d_p, c_p), (d_q, c_q) = totals(p), totals(q)
        roundabout = detour is not None and d_q > detour * d_p and c_q > c_p
        if not (c_q > factor * c_p or roundabout):
            continue
        if hops is None:
            hops = edges.matrix(allowed & (edges.d < d_max / 2))
        if trusted_edges(p, D, C, hops, d_max, corroboration, confirm=confirm).all():
            keep[edges.find(p[:-1], p[1:])] = True
            admitted[i] = True
    return admitted


def relax_cost_locally(keep: np.ndarray, edges: EdgeList, n_buffer: int, c_max: float,
                       allowed: Optional[np.ndarray] = None, relax: bool = True) -> Tuple[np.ndarray, float]:
    """Relax the cost cut-off around agents without a path until every goal is reachable (edits ``keep``,
    a mask over the problem's candidate ``edges``).

    For an agent without a path, the ``allowed`` edges (:func:`admissible`; default: all) leaving the
    region its start reaches (and those entering the region that reaches its goal) are admitted up to
    twice the cut-off, then four times, ...; the rest of the graph keeps ``c_max``. Each round widens
    both regions by one edge; once the cut-off passes the costliest allowed edge, the rounds go on
    without raising it while the regions still grow, so that a costly stretch many edges wide is
    crossed too. Returns ``(connected, c)``: which agents have a path, and the largest cut-off used
    (``c_max`` itself when nothing was relaxed, or when ``relax`` is false).
    """
    n = n_buffer
    k = (edges.n_nodes - n) // 2
    s_ids = np.arange(n, n + k)
    g_ids = np.arange(n + k, n + 2 * k)
    c = float(c_max)
    short = np.ones(len(edges), bool) if allowed is None else allowed
    c_top: Optional[float] = None  # the costliest allowed edge: no cut-off beyond it prunes anything
    grew = True
    while True:
        g = edges.matrix(keep, "one")
        fwd = np.isfinite(dijkstra(g, directed=True, indices=s_ids, unweighted=True))
        ok = fwd[np.arange(k), g_ids]
        if ok.all() or not relax or not math.isfinite(c):
            return ok, c
        if c_top is None:
            c_top = float(edges.c[short].max()) if short.any() else 0.0
        if c > c_top and not grew:
            return ok, c
        if c <= c_top:
            c *= 2.0
        bwd = np.isfinite(dijkstra(g.T.tocsr(), directed=True, indices=g_ids, unweighted=True))
        cheap = short & (edges.c < c)
        kept = int(keep.sum())
        for i in np.flatnonzero(~ok):
            keep |= cheap & fwd[i][edges.u]
            keep |= cheap & bwd[i][edges.v]
        grew = int(keep.sum()) > kept


__all__ = ["ConfirmFn", "admissible", "admit_cheaper_routes", "long_legs", "read_pairs",
           "relax_cost_locally", "route_from_predecessors", "shortest_routes", "trusted_edges"]
