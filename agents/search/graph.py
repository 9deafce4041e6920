"""The waypoint graph of search on the replay buffer.

Nodes are observations (drawn from a replay buffer or any list). A directed edge ``i -> j``
carries the predicted distance ``D[i, j]`` (expected steps) and the predicted cumulative cost
``C[i, j]`` of going from node ``i`` to node ``j`` with the goal-conditioned policy. Edges are
kept where ``D < d_max`` and ``C < c_max``; the graph is stored sparse (CSR), and saved as
``.npz`` so that planning runs without torch.

The graph never calls the environment; it takes matrices (from the critics, or any stand-in).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import zipfile
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np
from scipy import sparse


def _check_matrix(m: np.ndarray, name: str, shape: Optional[Tuple[int, int]] = None) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    if m.ndim != 2:
        raise ValueError(f"{name} must be a 2-D matrix, got shape {m.shape}")
    if shape is not None and m.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {m.shape}")
    if np.isnan(m).any():
        raise ValueError(f"{name} contains NaN")
    if (m < 0).any():
        raise ValueError(f"{name} contains negative entries (min {m.min():g})")
    return m


@dataclass
class WaypointGraph:
    """A directed graph over observations with predicted distance and cost on every edge.

    Attributes:
        distance: CSR matrix of predicted distances on the kept edges.
        cost: CSR matrix of predicted costs, same sparsity pattern as ``distance``.
        observations: the node observations, shape ``(N, ...)`` (optional for pure planning).
        d_max: the distance cut-off the graph was pruned with.
        c_max: the cost cut-off the graph was pruned with.
        positions: ground-truth node positions ``(N, 2)``, for plots and evaluation only
            (the planner never reads them).
    """

    distance: sparse.csr_matrix
    cost: sparse.csr_matrix
    observations: Optional[np.ndarray] = None
    d_max: float = 7.0
    c_max: float = np.inf
    positions: Optional[np.ndarray] = field(default=None, repr=False)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_matrices(
        cls,
        D: np.ndarray,
        C: Optional[np.ndarray] = None,
        d_max: float = 7.0,
        c_max: float = np.inf,
        observations: Optional[np.ndarray] = None,
        positions: Optional[np.ndarray] = None,
    ) -> "WaypointGraph":
        """Prune dense ``D`` (and ``C``; zeros if omitted) to the edges with ``D < d_max`` and ``C < c_max``.

        Self-loops are dropped. Zero distances are raised to a tiny positive value so that
        sparse storage keeps the edge.
        """
        D = _check_matrix(D, "D")
        if D.shape[0] != D.shape[1]:
            raise ValueError(f"D must be square, got shape {D.shape}")
        C = np.zeros_like(D) if C is None else _check_matrix(C, "C", D.shape)
        if not d_max > 0:
            raise ValueError(f"d_max must be > 0, got {d_max!r}")
        if not c_max > 0:
            raise ValueError(f"c_max must be > 0, got {c_max!r}")
        if observations is not None and len(observations) != D.shape[0]:
            raise ValueError(f"{len(observations)} observations for a {D.shape[0]}-node matrix")
        keep = (D < d_max) & (C < c_max)
        np.fill_diagonal(keep, False)
        rows, cols = np.nonzero(keep)
        n = D.shape[0]
        # store strictly positive values: a zero would vanish from the sparse structure
        dvals = np.maximum(D[rows, cols], 1e-9)
        cvals = np.maximum(C[rows, cols], 1e-12)
        dist = sparse.csr_matrix((dvals, (rows, cols)), shape=(n, n))
        cost = sparse.csr_matrix((cvals, (rows, cols)), shape=(n, n))
        return cls(dist, cost, observations, float(d_max), float(c_max), positions)

    @classmethod
    def from_agent(
        cls,
        agent,
        observations: np.ndarray,
        d_max: float = 7.0,
        c_max: float = np.inf,
        aggregate: str = "max",
        positions: Optional[np.ndarray] = None,
    ) -> "WaypointGraph":
        """Build the graph with an agent's critics: ``agent.pairwise_distance`` and ``agent.pairwise_cost``.

        ``aggregate`` picks the ensemble aggregation (``"max"`` is pessimistic, ``"mean"``).
        """
        obs = np.asarray(observations)
        D = agent.pairwise_distance(obs, obs, aggregate=aggregate)
        C = agent.pairwise_cost(obs, obs, aggregate=aggregate)
        return cls.from_matrices(D, C, d_max=d_max, c_max=c_max, observations=obs, positions=positions)

    # ------------------------------------------------------------------ properties
    @property
    def n_nodes(self) -> int:
        return self.distance.shape[0]

    @property
    def n_edges(self) -> int:
        return int(self.distance.nnz)

    def edge_arrays(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(src, dst, distance, cost)`` of every edge, as flat arrays in CSR order."""
        coo = self.distance.tocoo()
        return coo.row, coo.col, coo.data, self.cost_data()

    def cost_data(self) -> np.ndarray:
        """Edge costs aligned with ``self.distance.data`` (CSR order)."""
        coo = self.distance.tocoo()
        return np.asarray(self.cost.tocsr()[coo.row, coo.col]).ravel()

    def weight_matrix(self, objective: str = "distance", beta: float = 1.0) -> sparse.csr_matrix:
        """Edge weights for search: ``"distance"`` (D), ``"cost"`` (C) or ``"weighted"`` (D + beta C)."""
        d = self.distance.tocsr()
        if objective == "distance":
            return d
        w = d.copy()
        if objective == "cost":
            w.data = self.cost_data() + 1e-9  # keep zero-cost edges in the sparse structure
        elif objective == "weighted":
            if not beta >= 0:
                raise ValueError(f"beta must be >= 0, got {beta!r}")
            w.data = d.data + beta * self.cost_data()
        else:
            raise ValueError(f"unknown objective {objective!r}; choose 'distance', 'cost' or 'weighted'")
        return w

    def pruned(self, d_max: Optional[float] = None, c_max: Optional[float] = None) -> "WaypointGraph":
        """A copy keeping only the edges under tighter cut-offs."""
        d_max = self.d_max if d_max is None else d_max
        c_max = self.c_max if c_max is None else c_max
        src, dst, d, c = self.edge_arrays()
        keep = (d < d_max) & (c < c_max)
        n = self.n_nodes
        dist = sparse.csr_matrix((d[keep], (src[keep], dst[keep])), shape=(n, n))
        cost = sparse.csr_matrix((c[keep], (src[keep], dst[keep])), shape=(n, n))
        return WaypointGraph(dist, cost, self.observations, float(d_max), float(c_max), self.positions)

    # ------------------------------------------------------------------ endpoints
    def with_endpoints(
        self,
        d_from: np.ndarray,
        c_from: np.ndarray,
        d_to: np.ndarray,
        c_to: np.ndarray,
        d_direct: Optional[np.ndarray] = None,
        c_direct: Optional[np.ndarray] = None,
        observations: Optional[np.ndarray] = None,
    ) -> Tuple["WaypointGraph", np.ndarray, np.ndarray]:
        """Attach K start and K goal nodes; edges are pruned with this graph's cut-offs.

        Args:
            d_from, c_from: ``(K, N)`` predicted distance/cost from each start to every node.
            d_to, c_to: ``(N, K)`` predicted distance/cost from every node to each goal.
            d_direct, c_direct: ``(K, K)`` from start ``a`` to goal ``b``; only the diagonal
                (each start to its own goal) becomes an edge.
            observations: ``(2K, ...)`` start then goal observations, appended to the nodes.

        Returns:
            ``(graph, start_ids, goal_ids)``: the extended graph (N + 2K nodes) and the node ids
            of the starts and goals.
        """
        n = self.n_nodes
        k = np.shape(d_from)[0]
        d_from = _check_matrix(d_from, "d_from", (k, n))
        c_from = _check_matrix(c_from, "c_from", (k, n))
        d_to = _check_matrix(d_to, "d_to", (n, k))
        c_to = _check_matrix(c_to, "c_to", (n, k))
        start_ids = np.arange(n, n + k)
        goal_ids = np.arange(n + k, n + 2 * k)
        rows, cols, dv, cv = [], [], [], []

        def add(r, c, d, cc):
            keep = (d < self.d_max) & (cc < self.c_max)
            rows.append(np.broadcast_to(r, d.shape)[keep])
            cols.append(np.broadcast_to(c, d.shape)[keep])
            dv.append(np.maximum(d[keep], 1e-9))
            cv.append(np.maximum(cc[keep], 1e-12))

        add(start_ids[:, None], np.arange(n)[None, :], d_from, c_from)
        add(np.arange(n)[:, None], goal_ids[None, :], d_to, c_to)
        if d_direct is not None:
            dd = np.diag(_check_matrix(d_direct, "d_direct", (k, k)))
            cd = np.diag(_check_matrix(c_direct, "c_direct", (k, k))) if c_direct is not None else np.zeros(k)
            add(start_ids, goal_ids, dd, cd)
        src, dst, d, c = self.edge_arrays()
        rows.append(src)
        cols.append(dst)
        dv.append(d)
        cv.append(c)
        m = n + 2 * k
        r, cc_, dd_, ccv = (np.concatenate(x) for x in (rows, cols, dv, cv))
        dist = sparse.csr_matrix((dd_, (r, cc_)), shape=(m, m))
        cost = sparse.csr_matrix((ccv, (r, cc_)), shape=(m, m))
        obs = None
        if self.observations is not None and observations is not None:
            obs = np.concatenate([self.observations, np.asarray(observations, dtype=self.observations.dtype)])
        graph = WaypointGraph(dist, cost, obs, self.d_max, self.c_max, None)
        return graph, start_ids, goal_ids

    def attach_with_agent(self, agent, start_obs: np.ndarray, goal_obs: np.ndarray, aggregate: str = "max"):
        """Attach start and goal observations using the agent's critics (see :meth:`with_endpoints`)."""
        if self.observations is None:
            raise ValueError("this graph has no node observations to compare the endpoints with")
        s = np.asarray(start_obs)
        g = np.asarray(goal_obs)
        nodes = self.observations
        return self.with_endpoints(
            agent.pairwise_distance(s, nodes, aggregate=aggregate),
            agent.pairwise_cost(s, nodes, aggregate=aggregate),
            agent.pairwise_distance(nodes, g, aggregate=aggregate),
            agent.pairwise_cost(nodes, g, aggregate=aggregate),
            agent.pairwise_distance(s, g, aggregate=aggregate),
            agent.pairwise_cost(s, g, aggregate=aggregate),
            observations=np.concatenate([s, g]),
        )

    # ------------------------------------------------------------------ persistence
    def save(self, path: Union[str, Path]) -> None:
        """Save as ``.npz`` (no pickle): both weights, the cut-offs and, if present, observations and positions."""
        d = self.distance.tocsr()
        arrays = {
            "format": np.array("waypoint-graph-v1"),
            "shape": np.array(d.shape),
            "indptr": d.indptr, "indices": d.indices, "distance": d.data,
            "d_max": np.array(self.d_max), "c_max": np.array(self.c_max),
        }
        # the cost entries must follow the distance matrix's (row-sorted) order
        arrays["cost"] = self.cost_data() if d.nnz else np.zeros(0)
        if self.observations is not None:
            arrays["observations"] = np.asarray(self.observations)
        if self.positions is not None:
            arrays["positions"] = np.asarray(self.positions)
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: Union[str, Path]) -> "WaypointGraph":
        """Load a graph written by :meth:`save`; raise ``ValueError`` if the file is not one."""
        try:
            with np.load(path, allow_pickle=False) as z:
                if "format" not in z or str(z["format"]) != "waypoint-graph-v1":
                    raise ValueError(f"{path} is not a waypoint graph file (missing or wrong 'format')")
                shape = tuple(int(s) for s in z["shape"])
                d = sparse.csr_matrix((z["distance"], z["indices"], z["indptr"]), shape=shape)
                coo = d.tocoo()
                c = sparse.csr_matrix((z["cost"], (coo.row, coo.col)), shape=shape)
                obs = z["observations"] if "observations" in z else None
                pos = z["positions"] if "positions" in z else None
                return cls(d, c, obs, float(z["d_max"]), float(z["c_max"]), pos)
        except (OSError, KeyError, EOFError, ValueError, zipfile.BadZipFile) as exc:
            raise ValueError(f"cannot read waypoint graph {path}: {exc}") from exc


__all__ = ["WaypointGraph"]
