"""Fewer, better spread graph nodes: two-way consistency (Sparse Graphical Memory, Emmons et al. 2020).

A buffer graph of random observations holds many nodes at almost the same place, and every
extra node adds edges the critic can misjudge (a "wormhole": a short predicted hop through a
wall). Two nodes are interchangeable when they look the same to the critic both as starts and
as goals: their predicted distances to every kept node, and from every kept node, differ by at
most ``tau`` steps. :func:`two_way_consistent` keeps a node only if no node kept before it is
interchangeable with it, so the kept nodes are spread out by what the critic can tell apart,
not by positions (which the planner never sees).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .edges import EdgeList


def two_way_consistent(D: np.ndarray, tau: float, order: Optional[np.ndarray] = None) -> np.ndarray:
    """Indices of the nodes kept by two-way consistency merging (sorted).

    Args:
        D: predicted distances between every pair of nodes, ``(N, N)``.
        tau: largest difference (steps) of two interchangeable nodes' predicted distances, as starts
            (a row of ``D``) and as goals (a column), measured against the nodes kept so far.
        order: the order in which nodes are considered (default ``0..N-1``; a seeded permutation
            gives another equally good subset).
    """
    D = np.asarray(D, dtype=np.float64)
    n = len(D)
    if D.shape != (n, n):
        raise ValueError(f"D must be square, got shape {D.shape}")
    if not tau >= 0:
        raise ValueError(f"tau must be >= 0, got {tau!r}")
    order = np.arange(n) if order is None else np.asarray(order, dtype=np.int64)
    if sorted(order.tolist()) != list(range(n)):
        raise ValueError("order must be a permutation of the node indices")
    kept = np.zeros(n, dtype=bool)
    for i in order.tolist():
        k = np.flatnonzero(kept)
        if len(k):
            # as a start: distances to the kept nodes; as a goal: distances from them
            out_gap = np.abs(D[k][:, k] - D[i, k][None, :]).max(axis=1)
            in_gap = np.abs(D[k][:, k] - D[k, i][:, None]).max(axis=0)
            if np.any(np.maximum(out_gap, in_gap) <= tau):
                continue
        kept[i] = True
    return np.flatnonzero(kept)


def cap_out_edges(keep: np.ndarray, edges: EdgeList, k: int, n_buffer: Optional[int] = None) -> np.ndarray:
    """Keep at most ``k`` outgoing edges per buffer node (the ``k`` shortest by predicted distance, ties
    to the lower target id) in ``keep``, a mask over ``edges`` (edited and returned); edges from and to
    the first ``n_buffer`` nodes only are capped (default: all)."""
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k!r}")
    n = edges.n_nodes if n_buffer is None else int(n_buffer)
    sub = keep & (edges.u < n) & (edges.v < n)
    keep &= ~sub | (edges.ranks_within(edges.u, edges.d, sub) < k)
    return keep


__all__ = ["cap_out_edges", "two_way_consistent"]
