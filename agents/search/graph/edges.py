"""Edges of a graph as sorted lists: the form a problem graph is pruned and relaxed in.

A problem graph's nodes are the buffer's plus each agent's start and goal, and the critics score
every pair of them; but an edge exists only below ``d_max``, which on a large buffer is a small
share of the pairs. :class:`EdgeList` holds those short edges (source, target, predicted distance
and cost) sorted by source then target, so that every rule of the pruning is one pass over the
edges rather than over every pair (a one-agent replan on a 4000-node buffer reads about as many
edges as the buffer holds, against 16 million pairs), and a boolean array over the edges is an
edge mask.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
from scipy import sparse

#: sparse storage drops zeros, so kept edges carry at least this weight
MIN_WEIGHT = 1e-9


@dataclass(frozen=True)
class EdgeList:
    """Directed edges ``u[i] -> v[i]`` over ``n_nodes`` nodes, sorted by ``(u, v)``, with the critic's
    predicted distance ``d[i]`` and cost ``c[i]``."""

    u: np.ndarray
    v: np.ndarray
    d: np.ndarray
    c: np.ndarray
    n_nodes: int

    @classmethod
    def short(cls, D: np.ndarray, C: np.ndarray, d_max: float) -> "EdgeList":
        """Every pair ``u != v`` of the dense matrices with ``D[u, v] < d_max``."""
        mask = np.asarray(D) < d_max
        np.fill_diagonal(mask, False)
        u, v = np.nonzero(mask)
        return cls(u.astype(np.int64), v.astype(np.int64), np.asarray(D)[u, v].astype(np.float64),
                   np.asarray(C)[u, v].astype(np.float64), int(len(D)))

    @classmethod
    def from_dense_mask(cls, D: np.ndarray, C: np.ndarray, mask: np.ndarray) -> "EdgeList":
        """The edges where the boolean ``(N, N)`` ``mask`` holds (self-loops dropped)."""
        mask = np.array(mask, dtype=bool)
        np.fill_diagonal(mask, False)
        u, v = np.nonzero(mask)
        return cls(u.astype(np.int64), v.astype(np.int64), np.asarray(D)[u, v].astype(np.float64),
                   np.asarray(C)[u, v].astype(np.float64), int(len(D)))

    def __len__(self) -> int:
        return len(self.u)

    def keys(self) -> np.ndarray:
        """``u * n_nodes + v`` per edge: increasing, one number per pair."""
        return self.u * self.n_nodes + self.v

    def find(self, u: Any, v: Any) -> np.ndarray:
        """The index of each edge ``u[j] -> v[j]`` in this list, ``-1`` where it is not one."""
        u, v = np.asarray(u, np.int64).reshape(-1), np.asarray(v, np.int64).reshape(-1)
        if not len(u):
            return np.zeros(0, np.int64)
        keys = self.keys()
        if not len(keys):
            return -np.ones(len(u), np.int64)
        want = u * self.n_nodes + v
        at = np.minimum(np.searchsorted(keys, want), len(keys) - 1)
        return np.where(keys[at] == want, at, -1)

    def pairs(self, mask: Optional[np.ndarray] = None) -> np.ndarray:
        """``(E, 2)`` node pairs of the edges (where ``mask`` holds), in list order."""
        m = slice(None) if mask is None else mask
        return np.stack([self.u[m], self.v[m]], axis=1)

    def matrix(self, mask: Optional[np.ndarray] = None, weight: str = "d") -> sparse.csr_matrix:
        """CSR matrix of the edges (where ``mask`` holds) weighted by their distance ``"d"`` (raised to
        :data:`MIN_WEIGHT`, so that no edge vanishes) or by ``"one"``."""
        m = np.ones(len(self), bool) if mask is None else mask
        if weight == "d":
            data = np.maximum(self.d[m], MIN_WEIGHT)
        elif weight == "one":
            data = np.ones(int(m.sum()))
        else:
            raise ValueError(f"weight must be 'd' or 'one', got {weight!r}")
        n = self.n_nodes
        return sparse.csr_matrix((data, (self.u[m], self.v[m])), shape=(n, n))

    def dense(self, mask: Optional[np.ndarray] = None) -> np.ndarray:
        """The boolean ``(N, N)`` matrix of the edges (where ``mask`` holds): for small graphs and tests."""
        out = np.zeros((self.n_nodes, self.n_nodes), bool)
        m = slice(None) if mask is None else mask
        out[self.u[m], self.v[m]] = True
        return out

    def ranks_within(self, group: np.ndarray, by: np.ndarray, among: np.ndarray) -> np.ndarray:
        """Per edge of ``among`` (a mask), its rank by ``by`` among the edges of ``among`` with the same
        ``group`` value (0: the smallest; ties in list order); other edges get ``len(self)``."""
        idx = np.flatnonzero(among)
        rank = np.full(len(self), len(self), np.int64)
        if not len(idx):
            return rank
        order = idx[np.lexsort((by[idx], group[idx]))]
        g = group[order]
        starts = np.r_[0, np.flatnonzero(g[1:] != g[:-1]) + 1]
        first = np.repeat(starts, np.diff(np.r_[starts, len(order)]))
        rank[order] = np.arange(len(order)) - first
        return rank


def problem_edges(buffer: EdgeList, D: np.ndarray, C: np.ndarray, n_buffer: int, d_max: float) -> EdgeList:
    """Every edge a problem graph over ``D`` and ``C`` (layout of
    :class:`~agents.search.graph.build.ProblemGraph`: buffer nodes, starts, goals) may hold, whatever
    its cost: short (``D < d_max``), a start only left (towards buffer nodes and its own goal), a goal
    only entered. ``buffer``: the short edges among the buffer nodes (:meth:`EdgeList.short` of the
    buffer's matrices), which only the endpoints' are added to."""
    n, m = int(n_buffer), int(len(D))
    k = (m - n) // 2
    starts, goals = np.arange(n, n + k), np.arange(n + k, n + 2 * k)
    # start rows: towards buffer nodes and the own goal
    su, sv = np.nonzero(np.asarray(D[n:n + k, :n]) < d_max)
    su = su + n
    own = np.flatnonzero(np.asarray(D[starts, goals]) < d_max)
    su = np.concatenate([su, starts[own]])
    sv = np.concatenate([sv, goals[own]])
    s_order = np.lexsort((sv, su))
    su, sv = su[s_order], sv[s_order]
    # goal columns: from buffer nodes
    gv, gu = np.nonzero(np.asarray(D[:n, n + k:n + 2 * k]).T < d_max)  # (goal, buffer node) pairs
    gv = gv + n + k
    g_order = np.lexsort((gv, gu))
    gu, gv = gu[g_order], gv[g_order]
    # buffer rows hold buffer targets (< n) then goal targets (>= n + k): merge by key, then the start rows
    b_keys = buffer.u * m + buffer.v
    g_keys = gu * m + gv
    at = np.searchsorted(b_keys, g_keys)
    u = np.concatenate([np.insert(buffer.u, at, gu), su]).astype(np.int64)
    v = np.concatenate([np.insert(buffer.v, at, gv), sv]).astype(np.int64)
    du = np.asarray(D[np.concatenate([gu, su]), np.concatenate([gv, sv])], np.float64)
    cu = np.asarray(C[np.concatenate([gu, su]), np.concatenate([gv, sv])], np.float64)
    d = np.concatenate([np.insert(buffer.d, at, du[:len(gu)]), du[len(gu):]])
    c = np.concatenate([np.insert(buffer.c, at, cu[:len(gu)]), cu[len(gu):]])
    return EdgeList(u, v, d, c, m)


__all__ = ["EdgeList", "MIN_WEIGHT", "problem_edges"]
