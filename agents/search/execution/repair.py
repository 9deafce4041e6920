"""What a buffer graph learns from executions: edges that agents fail to traverse.

A learned critic misjudges some edges (a hop through a wall that two panoramas make look short, a
doorway the policy cannot pass): the planner keeps routing agents over them, episode after
episode. :class:`EdgeMemory` counts, per directed edge between buffer nodes, how often an agent
set off along it and got stuck, and how often one got through; an edge whose failures reach
``limit`` and outnumber its successes is removed from every later plan (the cleanup step of
Sparse Graphical Memory, Emmons et al. 2020). The memory belongs to the graph and to the policy
that drives on it, and is saved with the :class:`~agents.search.policy.SearchPolicy`.

It learns from the episodes it is shown: in an evaluation, from validation or training problems
only, never from the test problems (:attr:`EdgeMemory.frozen` stops it learning).
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ...run_folder import read_npz

Edge = Tuple[int, int]


class EdgeMemory:
    """Failure and success counts of directed edges between buffer nodes ``0..n_nodes-1``.

    Args:
        n_nodes: the buffer graph's node count (edges are checked against it).
        limit: failures at which an edge is removed (when they outnumber its successes).
    """

    def __init__(self, n_nodes: int, limit: int = 1) -> None:
        if int(n_nodes) < 1:
            raise ValueError(f"n_nodes must be >= 1, got {n_nodes!r}")
        if int(limit) < 1:
            raise ValueError(f"limit must be >= 1, got {limit!r}")
        self.n_nodes = int(n_nodes)
        self.limit = int(limit)
        self.failures: Dict[Edge, int] = {}
        self.successes: Dict[Edge, int] = {}
        #: a frozen memory keeps what it learned and records nothing more (test problems)
        self.frozen = False

    def _edge(self, u: int, v: int) -> Edge:
        u, v = int(u), int(v)
        if not (0 <= u < self.n_nodes and 0 <= v < self.n_nodes) or u == v:
            raise ValueError(f"an edge joins two buffer nodes in [0, {self.n_nodes}), got ({u}, {v})")
        return u, v

    def record_failure(self, u: int, v: int) -> None:
        """An agent set off along ``u -> v`` and got stuck (ignored while :attr:`frozen`)."""
        e = self._edge(u, v)
        if not self.frozen:
            self.failures[e] = self.failures.get(e, 0) + 1

    def record_success(self, u: int, v: int) -> None:
        """An agent got from ``u`` to ``v`` (ignored while :attr:`frozen`)."""
        e = self._edge(u, v)
        if not self.frozen:
            self.successes[e] = self.successes.get(e, 0) + 1

    def record_route(self, route: Sequence[int], reached: int, now: int, n_buffer: int) -> None:
        """An agent on ``route`` (node ids; its targets ``route[1:]``) moved from target ``reached`` on to
        target ``now``: record the buffer edges it got through (endpoints ``>= n_buffer`` are not)."""
        for q in range(max(reached, 1), min(now, len(route))):  # targets reached .. now - 1 were reached
            u, v = route[q - 1], route[q]
            if u < n_buffer and v < n_buffer and u != v:
                self.record_success(u, v)

    def is_removed(self, u: int, v: int) -> bool:
        f = self.failures.get((int(u), int(v)), 0)
        return f >= self.limit and f > self.successes.get((int(u), int(v)), 0)

    def removed(self) -> np.ndarray:
        """The removed edges, ``(E, 2)`` node pairs (sorted)."""
        edges = sorted(e for e in self.failures if self.is_removed(*e))
        return np.asarray(edges, dtype=np.int64).reshape(-1, 2)

    def update(self, other: "EdgeMemory") -> None:
        """Add another memory's counts over the same graph (e.g. from parallel workers)."""
        if other.n_nodes != self.n_nodes:
            raise ValueError(f"memories of graphs of {other.n_nodes} and {self.n_nodes} nodes cannot be merged")
        for mine, theirs in ((self.failures, other.failures), (self.successes, other.successes)):
            for e, c in theirs.items():
                mine[e] = mine.get(e, 0) + c

    def frozen_copy(self) -> "EdgeMemory":
        """A copy that keeps what this memory learned and learns nothing more (e.g. for test problems)."""
        out = EdgeMemory(self.n_nodes, self.limit)
        out.update(self)
        out.frozen = True
        return out

    def __len__(self) -> int:
        return len(self.removed())

    def __repr__(self) -> str:
        return (f"EdgeMemory(n_nodes={self.n_nodes}, limit={self.limit}, failed edges={len(self.failures)}, "
                f"removed={len(self)}, frozen={self.frozen})")

    # ------------------------------------------------------------------ persistence
    def arrays(self, prefix: str = "memory_") -> Dict[str, np.ndarray]:
        """The memory as arrays (for ``np.savez``), keys starting with ``prefix``."""

        def table(d: Dict[Edge, int]) -> np.ndarray:
            return np.asarray([(u, v, c) for (u, v), c in sorted(d.items())], dtype=np.int64).reshape(-1, 3)

        return {f"{prefix}failures": table(self.failures), f"{prefix}successes": table(self.successes),
                f"{prefix}meta": np.asarray([self.n_nodes, self.limit], dtype=np.int64)}

    @classmethod
    def from_arrays(cls, arrays, prefix: str = "memory_") -> "EdgeMemory":
        """The memory saved by :meth:`arrays`; a malformed one raises ``ValueError``."""
        try:
            n_nodes, limit = (int(x) for x in np.asarray(arrays[f"{prefix}meta"]).reshape(2))
            tables = [np.asarray(arrays[f"{prefix}{k}"], dtype=np.int64).reshape(-1, 3)
                      for k in ("failures", "successes")]
        except (KeyError, ValueError, TypeError) as e:
            raise ValueError(f"not a saved edge memory: {e}") from None
        memory = cls(n_nodes, limit)
        for target, t in zip((memory.failures, memory.successes), tables):
            for u, v, c in t.tolist():
                if c < 0:
                    raise ValueError(f"not a saved edge memory: negative count on edge ({u}, {v})")
                target[memory._edge(u, v)] = int(c)
        return memory

    def save(self, path: Union[str, Path]) -> None:
        """Write the memory to ``path`` (``.npz``)."""
        arrays: Dict[str, Any] = self.arrays()
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: Union[str, Path]) -> "EdgeMemory":
        """Read a memory written by :meth:`save`, whole and without pickle; a missing, truncated,
        corrupt or malformed file raises ``ValueError`` naming ``path``."""
        arrays = read_npz(path, "saved edge memory")
        try:
            return cls.from_arrays(arrays)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None


def past_failed_waypoints(route: Sequence[int], goal: int, D: np.ndarray, failed: Sequence[int],
                          times: int = 2, detour: float = 1.5,
                          straight: Optional[Callable[[int, int], float]] = None) -> List[int]:
    """The positions in ``route`` to keep once the waypoints an agent failed on again and again are skipped.

    A learned policy can fail on one waypoint episode after episode (one in a doorway, which it
    hovers in front of) and pass it when it heads for the node beyond. A replan that finds no way
    but through such a waypoint (failed ``times`` times or more) heads past it instead, where the
    critic finds going straight on at most ``detour`` times as long as going through it (a wall
    between would make it far longer).

    Args:
        route: node ids of a new route (its start first, its goal left out).
        goal: the goal's node id; ``D``: predicted distances between the nodes.
        failed: the waypoints the agent failed to reach so far (one entry per failure).
        straight: ``straight(u, w)``, the critic's distance from node ``u`` to node ``w`` (default:
            ``D[u, w]``); for a problem graph whose ``D`` is exact only below ``d_max`` (beyond, a bound).
    """
    straight = straight if straight is not None else (lambda u, w: float(D[u, w]))
    fails = Counter(failed)
    keep = list(range(len(route)))
    i = 1
    while i < len(keep):
        u, v = route[keep[i - 1]], route[keep[i]]
        w = route[keep[i + 1]] if i + 1 < len(keep) else goal
        if fails[v] >= times and straight(u, w) <= detour * (D[u, v] + D[v, w]):
            del keep[i]
        else:
            i += 1
    return keep


def near_either_way(D: np.ndarray, node: int, radius: float, n: Union[int, None] = None) -> np.ndarray:
    """Mask of the first ``n`` nodes (all without it) within ``radius`` predicted steps of ``node``
    in ``D``, either way (the critic's distance is not symmetric)."""
    n = D.shape[0] if n is None else n
    return np.minimum(D[node, :n], D[:n, node]) < radius


def edges_near(D: np.ndarray, u: int, v: int, radius: float) -> np.ndarray:
    """``(E, 2)`` node pairs: the edge ``u -> v`` and every edge from a node within ``radius``
    predicted steps of ``u`` to one within ``radius`` of ``v``.

    An agent that failed on ``u -> v`` because the critic takes two far places for near ones (a
    wormhole: two panoramas alike) finds the same shortcut again between the nodes right by them;
    its replans leave them all out.
    """
    a = np.union1d(np.flatnonzero(near_either_way(D, u, radius)), [u])
    b = np.union1d(np.flatnonzero(near_either_way(D, v, radius)), [v])
    pairs = np.stack(np.meshgrid(a, b, indexing="ij"), axis=-1).reshape(-1, 2)
    return pairs[pairs[:, 0] != pairs[:, 1]]


__all__ = ["Edge", "EdgeMemory", "edges_near", "near_either_way", "past_failed_waypoints"]
