"""The waypoint graph of search on the replay buffer.

Nodes are observations (drawn from a replay buffer or any list). A directed edge ``i -> j``
carries the predicted distance ``D[i, j]`` (expected steps) and the predicted cumulative cost
``C[i, j]`` of going from node ``i`` to node ``j`` with the goal-conditioned policy. Edges are
kept where ``D < d_max`` and ``C < c_max``; the graph is stored sparse (CSR), and saved as
``.npz`` so that planning runs without torch.

The graph never calls the environment; it takes matrices (from the critics, or any stand-in).
"""
from __future__ import annotations

import functools
import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np
from scipy import sparse

from ...run_folder import read_npz
from .edges import MIN_WEIGHT, EdgeList, problem_edges
from .pruning import admissible, admit_cheaper_routes, long_legs, relax_cost_locally
from .sparsify import cap_out_edges

#: ``pairwise(obs_a, obs_b) -> (D, C)``, each of shape ``(len(obs_a), len(obs_b))``.
PairwiseFn = Callable[[np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray]]


class NodePairwise:
    """``pairwise(obs_a, obs_b) -> (D, C)`` of a critic model that encodes the graph's nodes once.

    ``model`` is a :class:`~agents.algorithm.SafeGoalTD3` (anything with ``pairwise(a, b,
    aggregate=...)``; with ``encode_observations(obs)`` too, the codes of ``nodes`` are computed
    on the first call that passes that very array and reused after). A planner scores its nodes
    against every new start and goal, at every replan, so this saves encoding them each time
    (1000 panoramas: two passes of the image encoder per replan). The result is the same as
    ``model.pairwise(a, b, aggregate=aggregate)``. The model must not train while this is in use.
    """

    def __init__(self, model, nodes: np.ndarray, aggregate: str = "max",
                 bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None) -> None:
        self.model = model
        self.nodes = nodes
        self.aggregate = aggregate
        #: ``bound(obs_a, obs_b) -> (N, M)``: a lower bound of the distance in steps that costs no
        #: critic call (e.g. the environment's ``min_steps``); :meth:`within` scores only the pairs
        #: it puts below ``d_max``
        self.bound = bound
        self._codes = None

    def _arg(self, x):
        if x is not self.nodes or not hasattr(self.model, "encode_observations"):
            return x
        if self._codes is None:
            self._codes = self.model.encode_observations(self.nodes)
        return self._codes

    def __call__(self, obs_a: np.ndarray, obs_b: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        return self.model.pairwise(self._arg(obs_a), self._arg(obs_b), aggregate=self.aggregate)

    def within(self, obs_a: np.ndarray, obs_b: np.ndarray, d_max: float) -> Tuple[np.ndarray, np.ndarray]:
        """``(D, C)`` exact where ``D < d_max``; elsewhere ``D >= d_max`` and ``C = inf``.

        With the pessimistic aggregate (``"max"``), pairs that one member of the distance
        ensemble already puts at ``d_max`` or beyond are not scored further (see
        ``SafeGoalPolicy.pairwise``); with another aggregate, or a model without that option,
        every pair is scored as by the call itself.
        """
        if self.aggregate != "max" or "within" not in inspect.signature(self.model.pairwise).parameters:
            return self(obs_a, obs_b)
        if self.bound is not None and hasattr(self.model, "pairwise_at"):
            # pairs the bound puts at d_max or beyond keep the bound and an infinite cost; only
            # the others are read by the critics
            D = np.array(self.bound(obs_a, obs_b), dtype=np.float32)
            if D.shape != (len(obs_a), len(obs_b)):
                raise ValueError(f"bound returned shape {D.shape}, expected {(len(obs_a), len(obs_b))}")
            C = np.full(D.shape, np.inf, dtype=np.float32)
            rows, cols = np.nonzero(D < d_max)
            if len(rows):
                D[rows, cols], C[rows, cols] = self.model.pairwise_at(self._arg(obs_a), self._arg(obs_b), rows, cols,
                                                                      within=d_max)
            return D, C
        # blocks of 8192 pairs: about 20% faster than the default 2048 here (few pairs per block get
        # past the first member)
        return self.model.pairwise(self._arg(obs_a), self._arg(obs_b), aggregate=self.aggregate,
                                   chunk_size=8192, within=d_max)


#: sparse storage drops zeros, so kept edges carry at least this cost (their distances:
#: :data:`~agents.search.graph.edges.MIN_WEIGHT`)
_MIN_COST = 1e-12


def _short_and_cheap(D: np.ndarray, C: np.ndarray, d_max: float, c_max: float) -> np.ndarray:
    """The pruning rule of every graph in this package: ``D < d_max`` and ``C < c_max``."""
    return (D < d_max) & (C < c_max)


def edge_mask(D: np.ndarray, C: np.ndarray, d_max: float, c_max: float) -> np.ndarray:
    """Boolean ``(N, N)`` mask of the edges a graph over dense ``D``, ``C`` keeps (no self-loops)."""
    keep = _short_and_cheap(D, C, d_max, c_max)
    np.fill_diagonal(keep, False)
    return keep


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


# ---------------------------------------------------------------------- graph files
def _node_space(space: Any) -> Any:
    """The space of one node observation in a model's observation space (its ``"observation"``)."""
    spaces_ = getattr(space, "spaces", None)
    if isinstance(spaces_, dict) and "observation" in spaces_:
        return spaces_["observation"]
    return space


def env_record(observations: Optional[np.ndarray], env_id: Optional[str]) -> Dict[str, np.ndarray]:
    """The arrays a graph file records about where it was made: ``env_id`` and ``observation_shape``."""
    out: Dict[str, np.ndarray] = {}
    if env_id:
        out["env_id"] = np.array(str(env_id).split(":")[-1])
    if observations is not None:
        out["observation_shape"] = np.asarray(np.shape(observations)[1:], dtype=np.int64)
    return out


def check_graph_nodes(path: Union[str, Path], arrays: Dict[str, np.ndarray], observations: Optional[np.ndarray],
                      models: Iterable[Any] = (), env_id: Optional[str] = None,
                      observation_space: Any = None) -> None:
    """Check a graph file's node observations against what the file records and the models or
    environment it is loaded with; ``ValueError`` naming ``path`` and the mismatch.

    - the recorded ``env_id`` (files that record one) must be the id of ``env_id`` and of every
      model that names its environment (``model.env_id``);
    - the node observations must have the recorded ``observation_shape`` and the shape of one
      observation of ``observation_space`` and of every model's space (its ``"observation"``);
    - they must be finite and inside that space's bounds.
    """
    models = [m for m in models if m is not None]
    recorded = str(arrays["env_id"]) if "env_id" in arrays else None
    if recorded is not None:
        wanted = [("the environment", env_id)] + [(type(m).__name__, getattr(m, "env_id", None)) for m in models]
        for who, eid in wanted:
            if eid and str(eid).split(":")[-1] != recorded:
                raise ValueError(f"{path} was made on {recorded!r}; {who} is of {str(eid).split(':')[-1]!r}")
    if observations is None:
        return
    obs = np.asarray(observations)
    if "observation_shape" in arrays:
        shape = tuple(int(s) for s in np.asarray(arrays["observation_shape"]).reshape(-1))
        if obs.shape[1:] != shape:
            raise ValueError(f"{path}: its node observations have shape {obs.shape[1:]}, the file records {shape}")
    if obs.dtype.kind not in "biuf":
        raise ValueError(f"{path}: its node observations are not numbers (dtype {obs.dtype})")
    if obs.dtype.kind == "f" and not np.isfinite(obs).all():
        bad = np.flatnonzero(~np.isfinite(obs.reshape(len(obs), -1)).all(axis=1))
        raise ValueError(f"{path}: {len(bad)} node observations are not finite (NaN or infinity), "
                         f"first at node {int(bad[0])}")
    spaces_ = [("the environment", _node_space(observation_space))]
    spaces_ += [(type(m).__name__, _node_space(getattr(m, "observation_space", None))) for m in models]
    for who, space in spaces_:
        space_shape = getattr(space, "shape", None)
        if space_shape is None:
            continue
        if obs.shape[1:] != tuple(space_shape):
            raise ValueError(f"{path}: its node observations have shape {obs.shape[1:]}, {who} takes "
                             f"{tuple(space_shape)}")
        low, high = getattr(space, "low", None), getattr(space, "high", None)
        if low is not None and high is not None and len(obs):
            outside = ~((obs >= low) & (obs <= high)).reshape(len(obs), -1).all(axis=1)
            if outside.any():
                bad = np.flatnonzero(outside)
                raise ValueError(f"{path}: {len(bad)} node observations lie outside the bounds of {who}'s "
                                 f"observation space (first at node {int(bad[0])})")

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
        return cls.from_mask(D, C, edge_mask(D, C, d_max, c_max), observations, d_max, c_max, positions)

    @classmethod
    def from_mask(
        cls,
        D: np.ndarray,
        C: np.ndarray,
        keep: np.ndarray,
        observations: Optional[np.ndarray] = None,
        d_max: float = 7.0,
        c_max: float = np.inf,
        positions: Optional[np.ndarray] = None,
    ) -> "WaypointGraph":
        """The graph of dense ``D`` and ``C`` on the edges where the boolean ``keep`` is true (no
        self-loops).

        Zero weights are raised to a tiny positive value so that sparse storage keeps the edge.
        """
        return cls.from_edges(EdgeList.from_dense_mask(D, C, keep), None, observations, d_max, c_max, positions)

    @classmethod
    def from_edges(
        cls,
        edges: EdgeList,
        keep: Optional[np.ndarray] = None,
        observations: Optional[np.ndarray] = None,
        d_max: float = 7.0,
        c_max: float = np.inf,
        positions: Optional[np.ndarray] = None,
    ) -> "WaypointGraph":
        """The graph of an :class:`~agents.search.graph.edges.EdgeList` (where the boolean array ``keep``
        over its edges holds; default: all of them).

        Zero weights are raised to a tiny positive value so that sparse storage keeps the edge.
        """
        m = slice(None) if keep is None else keep
        rows, cols = edges.u[m], edges.v[m]
        n = edges.n_nodes
        # store strictly positive values: a zero would vanish from the sparse structure
        dist = sparse.csr_matrix((np.maximum(edges.d[m], MIN_WEIGHT), (rows, cols)), shape=(n, n))
        cost = sparse.csr_matrix((np.maximum(edges.c[m], _MIN_COST), (rows, cols)), shape=(n, n))
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
        keep = _short_and_cheap(d, c, d_max, c_max)
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
            keep = _short_and_cheap(d, cc, self.d_max, self.c_max)
            rows.append(np.broadcast_to(r, d.shape)[keep])
            cols.append(np.broadcast_to(c, d.shape)[keep])
            dv.append(np.maximum(d[keep], MIN_WEIGHT))
            cv.append(np.maximum(cc[keep], _MIN_COST))

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
    def save(self, path: Union[str, Path], env_id: Optional[str] = None) -> None:
        """Save as ``.npz`` (no pickle): both weights, the cut-offs and, if present, observations and
        positions; with them the shape of one observation and ``env_id`` (the environment the nodes
        come from), which :meth:`load` checks."""
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
        arrays.update(env_record(self.observations, env_id))
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: Union[str, Path], env_id: Optional[str] = None, observation_space: Any = None,
             models: Sequence[Any] = ()) -> "WaypointGraph":
        """Load a graph written by :meth:`save`, read whole; raise ``ValueError`` naming ``path`` if
        the file is not one (missing, truncated, corrupt, inconsistent weights).

        ``env_id``, ``observation_space`` and ``models`` (e.g. the critic that scores new endpoints
        against the nodes) are checked against the file: the environment it records (files that
        record one), the shape of its node observations, and that they are finite and inside the
        space's bounds (see :func:`check_graph_nodes`).
        """
        z = read_npz(path, "waypoint graph file")
        if "format" not in z or str(z["format"]) != "waypoint-graph-v1":
            raise ValueError(f"{path} is not a waypoint graph file (missing or wrong 'format')")
        try:
            shape = tuple(int(s) for s in z["shape"])
            d = sparse.csr_matrix((z["distance"], z["indices"], z["indptr"]), shape=shape)
            d.check_format(full_check=True)
            coo = d.tocoo()
            c = sparse.csr_matrix((z["cost"], (coo.row, coo.col)), shape=shape)
            d_max, c_max = float(z["d_max"]), float(z["c_max"])
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            raise ValueError(f"{path} is not a waypoint graph file: {type(exc).__name__}: {exc}") from exc
        if len(z["distance"]) and (not np.isfinite(z["distance"]).all() or (z["distance"] < 0).any()):
            raise ValueError(f"{path}: its edge distances must be finite and >= 0")
        if len(z["cost"]) and (np.isnan(z["cost"]).any() or (z["cost"] < 0).any()):
            raise ValueError(f"{path}: its edge costs must be numbers >= 0")
        obs = z.get("observations")
        pos = z.get("positions")
        for name, arr in (("observations", obs), ("positions", pos)):
            if arr is not None and len(arr) != shape[0]:
                raise ValueError(f"{path}: it holds {len(arr)} node {name} for a graph of {shape[0]} nodes")
        check_graph_nodes(path, z, obs, models, env_id, observation_space)
        return cls(d, c, obs, d_max, c_max, pos)


# ---------------------------------------------------------------------- problem graphs
class BorderedMatrix:
    """A dense ``(N + M, N + M)`` matrix kept as a shared ``(N, N)`` block (not copied) and its
    ``M`` border rows and columns: what a problem graph of a few agents keeps of ``D`` or ``C``
    once planned, instead of a copy of the buffer's matrix per replan.

    Indexing by two integers, or by an integer and a slice, reads the parts without building the
    whole matrix; any other use (``np.asarray``, fancy indexing) builds it.

    Args:
        inner: the shared ``(N, N)`` block.
        rows: the last ``M`` rows, ``(M, N + M)``.
        cols: the last ``M`` columns, ``(N + M, M)``.
    """

    def __init__(self, inner: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
        n, m = inner.shape[0], rows.shape[0]
        if inner.shape != (n, n) or rows.shape != (m, n + m) or cols.shape != (n + m, m):
            raise ValueError(f"a bordered matrix needs (N, N), (M, N + M) and (N + M, M) parts, got "
                             f"{inner.shape}, {rows.shape} and {cols.shape}")
        self.inner, self.rows, self.cols, self.n = inner, rows, cols, n
        self.shape = (n + m, n + m)
        self.dtype = rows.dtype
        self.ndim = 2

    @classmethod
    def of(cls, full: np.ndarray, inner: np.ndarray) -> "BorderedMatrix":
        """``full`` kept as ``inner`` (which must equal its top-left block) and its border."""
        n = inner.shape[0]
        return cls(inner, full[n:, :].copy(), full[:, n:].copy())

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, tuple) and len(key) == 2:
            i, j = key
            n = self.n
            if isinstance(i, (int, np.integer)) and not isinstance(i, bool):
                i = int(i) % self.shape[0]
                if i >= n:
                    return self.rows[i - n][j]
                if isinstance(j, (int, np.integer)) and not isinstance(j, bool):
                    j = int(j) % self.shape[1]
                    return self.inner[i, j] if j < n else self.cols[i, j - n]
                if isinstance(j, slice):
                    return np.concatenate([self.inner[i], self.cols[i]])[j]
            elif isinstance(i, slice) and isinstance(j, (int, np.integer)) and not isinstance(j, bool):
                j = int(j) % self.shape[1]
                if j >= n:
                    return self.cols[i, j - n]
                return np.concatenate([self.inner[:, j], self.rows[:, j]])[i]
        return np.asarray(self)[key]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        n = self.n
        out = np.empty(self.shape, dtype=self.dtype if dtype is None else dtype)
        out[:n, :n] = self.inner
        out[n:, :] = self.rows
        out[:, n:] = self.cols
        return out


@dataclass
class ProblemGraph:
    """The graph one planning problem is solved on: buffer nodes plus each agent's endpoints.

    Node ids are ``0..N-1`` for the buffer nodes, ``N..N+K-1`` for the K starts and
    ``N+K..N+2K-1`` for the K goals (in agent order).

    Attributes:
        observations: the node observations, ``(N + 2K, ...)``.
        D, C: dense predicted distance and cost between every pair of nodes; with a critic
            that scores only the close pairs (:meth:`NodePairwise.within`), a pair of an
            endpoint and another node at ``d_max`` or beyond holds a lower bound of its
            distance and an infinite cost.
        graph: the pruned graph (:class:`WaypointGraph`) the search runs on.
        n_buffer: N, the number of buffer nodes.
        c_max: the largest cost cut-off used (above the one asked for where it was relaxed).
        connected: per agent, whether its goal is reachable from its start in ``graph``.
    """

    observations: np.ndarray
    D: np.ndarray
    C: np.ndarray
    graph: WaypointGraph
    n_buffer: int
    c_max: float
    connected: np.ndarray

    @property
    def n_agents(self) -> int:
        return (len(self.observations) - self.n_buffer) // 2

    def compact(self, D: np.ndarray, C: np.ndarray) -> "ProblemGraph":
        """This problem graph with ``D`` and ``C`` kept as :class:`BorderedMatrix` over the buffer's
        own matrices ``D`` and ``C`` (the planner's, which its top-left blocks equal): what is
        worth keeping of a problem of one agent on a large graph (its dense matrices would be
        a copy of the buffer's)."""
        n = self.n_buffer
        if D.shape != (n, n) or C.shape != (n, n):
            raise ValueError(f"the buffer's matrices must be ({n}, {n}), got {D.shape} and {C.shape}")
        return ProblemGraph(self.observations, BorderedMatrix.of(self.D, D),  # type: ignore[arg-type]
                            BorderedMatrix.of(self.C, C), self.graph, n,  # type: ignore[arg-type]
                            self.c_max, self.connected)

    @property
    def start_ids(self) -> List[int]:
        return list(range(self.n_buffer, self.n_buffer + self.n_agents))

    @property
    def goal_ids(self) -> List[int]:
        k = self.n_agents
        return list(range(self.n_buffer + k, self.n_buffer + 2 * k))


def attach_endpoints(
    observations: np.ndarray, D: np.ndarray, C: np.ndarray, pairwise: PairwiseFn,
    starts: np.ndarray, goals: np.ndarray, d_max: Optional[float] = None,
    out: Optional[Tuple[np.ndarray, np.ndarray]] = None,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense ``(D, C)`` over buffer nodes + starts + goals (``pairwise`` scores the new pairs), and
    the observations in that order.

    With ``d_max``, a ``pairwise`` that has a ``within(obs_a, obs_b, d_max)`` method (as
    :class:`NodePairwise`) scores only the new pairs closer than ``d_max`` exactly; the others
    get a distance ``>= d_max`` and an infinite cost. Every edge, proximity and nearness test of
    the planner asks for distances below ``d_max`` (or below smaller radii), so its answers do
    not change; the matrices of such a problem are exact only below ``d_max``.

    ``out``: two ``(N + M, N + M)`` matrices whose top-left blocks hold ``D`` and ``C`` already
    (those of an earlier call with as many endpoints, that nothing uses any more): only their
    borders are written, and they are returned. Copying a large buffer's matrices is most of the
    work of attaching one agent's endpoints.
    """
    n, m = len(observations), 2 * len(starts)
    ends = np.concatenate([starts, goals])
    within = getattr(pairwise, "within", None)
    score = pairwise if d_max is None or within is None else functools.partial(within, d_max=float(d_max))
    d_ne, c_ne = score(observations, ends)
    d_en, c_en = score(ends, observations)
    d_ee, c_ee = score(ends, ends)
    if out is not None and out[0].shape == (n + m, n + m) and out[1].shape == (n + m, n + m):
        D2, C2 = out
    else:
        D2, C2 = np.empty((n + m, n + m)), np.empty((n + m, n + m))
        D2[:n, :n], C2[:n, :n] = D, C
    D2[:n, n:], D2[n:, :n], D2[n:, n:] = d_ne, d_en, d_ee
    C2[:n, n:], C2[n:, :n], C2[n:, n:] = c_ne, c_en, c_ee
    return D2, C2, np.concatenate([observations, ends])


def problem_edge_mask(edges: EdgeList, n_buffer: int, c_max: float, endpoint_edges: int) -> np.ndarray:
    """Which of a problem's candidate ``edges`` (:func:`~agents.search.graph.edges.problem_edges`) its
    graph keeps under cut-off ``c_max``: a boolean array over them.

    The rule of :func:`edge_mask` (the candidates are short already), plus: every start keeps its
    ``endpoint_edges`` cheapest outgoing edges to buffer nodes (every goal its cheapest incoming ones)
    whatever ``c_max``, so that an agent that starts or ends in a costly place is not cut off.
    """
    n = n_buffer
    k = (edges.n_nodes - n) // 2
    keep = edges.c < c_max
    e = min(int(endpoint_edges), n)
    if e > 0 and k:
        from_start = (edges.u >= n) & (edges.u < n + k) & (edges.v < n)
        keep |= from_start & (edges.ranks_within(edges.u, edges.c, from_start) < e)
        into_goal = (edges.v >= n + k) & (edges.u < n)
        keep |= into_goal & (edges.ranks_within(edges.v, edges.c, into_goal) < e)
    return keep


def place_distances(pairwise: PairwiseFn, observations: np.ndarray, places: np.ndarray,
                    d_max: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray]:
    """``(to_place, from_place)``: the predicted distances from every observation to every place ``(N, P)``
    and back ``(P, N)`` (``d_max`` as for :func:`attach_endpoints`)."""
    within = getattr(pairwise, "within", None)
    score = pairwise if d_max is None or within is None else functools.partial(within, d_max=float(d_max))
    return score(observations, places)[0], score(places, observations)[0]


#: :func:`passing_edges` reads ``known_pairs`` where at most this many other nodes (a replan's starts and
#: goals) are to be compared, all places at once; with more it compares every pair place by place
_ONE_PASS_ENDPOINTS = 8


def _passing_block(D: np.ndarray, to_place: np.ndarray, from_place: np.ndarray, us: np.ndarray, vs: np.ndarray,
                   slack: float, d_max: Optional[float]) -> Tuple[np.ndarray, np.ndarray]:
    """The pairs of ``us x vs`` whose edge passes one place (``to_place[u]``, ``from_place[v]``: the
    distances to and from it): ``(u, v)`` arrays."""
    if not (len(us) and len(vs)):
        return us[:0], vs[:0]
    d = np.asarray(D[np.ix_(us, vs)])
    through = to_place[us][:, None] + from_place[vs][None, :] <= d + slack
    if d_max is not None:
        through &= d < d_max
    a, b = np.nonzero(through)
    return us[a], vs[b]


def _near_place(to_place: np.ndarray, from_place: np.ndarray, slack: float,
                d_max: Optional[float]) -> Tuple[np.ndarray, np.ndarray]:
    """The nodes an edge through a place may start and end at: an edge (shorter than ``d_max``)
    through it comes within ``d_max + slack`` of it at both ends."""
    limit = np.inf if d_max is None else float(d_max) + slack
    return np.flatnonzero(to_place < limit), np.flatnonzero(from_place < limit)


def place_passing(D: np.ndarray, to_place: np.ndarray, from_place: np.ndarray, slack: float,
                  d_max: Optional[float] = None) -> np.ndarray:
    """The edges among the nodes of ``D`` that pass one place, ``to_place[u]`` / ``from_place[v]`` being
    the distances to and from it (``(N,)`` each): ``(E, 2)`` node pairs, row-major, the rule of
    :func:`passing_edges`. A buffer's are kept per place by a planner (its replans around parked
    agents ask for the same places again and again)."""
    us, vs = _near_place(to_place, from_place, slack, d_max)
    u, v = _passing_block(D, to_place, from_place, us, vs, slack, d_max)
    return np.stack([u, v], axis=1).astype(np.int64)


def passing_edges(D: np.ndarray, observations: np.ndarray, pairwise: PairwiseFn, places: np.ndarray,
                  slack: float, d_max: Optional[float] = None,
                  known: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                  known_pairs: Optional[Sequence[np.ndarray]] = None) -> np.ndarray:
    """The edges ``u -> v`` among ``observations`` (distances ``D``) that pass one of ``places``: going
    through it is at most ``slack`` longer than the edge. An edge that ends at such a place passes it
    too. ``(E, 2)`` node pairs, sorted. ``d_max`` as for :func:`attach_endpoints`; with it, only pairs
    closer than ``d_max`` (the edges a problem graph may hold) are listed. ``known``: what
    :func:`place_distances` gives for the first observations (a buffer's, whose distances to parked
    agents do not change from one replan to the next); only the others are scored. ``known_pairs``
    (with ``known``): per place, the pairs among those first observations that pass it
    (:func:`place_passing` of their block of ``D``); then, where the others are few, only pairs with
    one of them are compared."""
    have = 0 if known is None else len(known[0])
    if known_pairs is not None and (known is None or len(known_pairs) != len(places)):
        raise ValueError("known_pairs needs known, and one array of pairs per place")
    to_place, from_place = place_distances(pairwise, observations[have:], places, d_max)
    if known is not None:
        to_place = np.concatenate([known[0], to_place], axis=0)
        from_place = np.concatenate([known[1], from_place], axis=1)
    m = len(observations)
    found = []
    if known_pairs is None or m - have > _ONE_PASS_ENDPOINTS:
        for j in range(len(places)):
            us, vs = _near_place(to_place[:, j], from_place[j], slack, d_max)
            u, v = _passing_block(D, to_place[:, j], from_place[j], us, vs, slack, d_max)
            found.append(u.astype(np.int64) * m + v)
    else:
        found += [np.asarray(k, dtype=np.int64).reshape(-1, 2) @ np.array([m, 1], np.int64) for k in known_pairs]
        # the pairs with another node, all places at once: an edge passes one of them where the shortest
        # way through a place it may start and end near is short enough
        limit = np.inf if d_max is None else float(d_max) + slack
        to_near = np.where(to_place < limit, to_place, np.inf)  # (m, P)
        from_near = np.where(from_place < limit, from_place, np.inf)  # (P, m)
        every, buffer = np.arange(m, dtype=np.int64), np.arange(have, dtype=np.int64)
        for e in range(have, m):
            ends = np.full(m, e, np.int64)
            for rows, cols, through in ((every, ends, (to_near + from_near[:, e]).min(axis=1)),  # u -> e
                                        (ends[:have], buffer, (to_near[e][:, None] + from_near[:, :have]).min(axis=0))):
                d = np.asarray(D[rows, cols], dtype=np.float64)
                ok = np.isfinite(through) & (through <= d + slack)
                if d_max is not None:
                    ok &= d < d_max
                found.append(rows[ok] * m + cols[ok])
    keys = np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)
    pairs = np.stack([keys // m, keys % m], axis=1)
    return pairs[pairs[:, 0] != pairs[:, 1]]


def check_endpoints(observations: np.ndarray, starts: np.ndarray, goals: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``starts`` and ``goals`` as arrays of the nodes' dtype; ``ValueError`` unless both are ``(K, ...)`` of the
    nodes' observation shape and finite."""
    starts = np.asarray(starts, dtype=observations.dtype)
    goals = np.asarray(goals, dtype=observations.dtype)
    if starts.shape != goals.shape or starts.shape[1:] != observations.shape[1:]:
        raise ValueError(f"starts {starts.shape} and goals {goals.shape} must both be (K, "
                         f"{', '.join(map(str, observations.shape[1:]))})")
    for name, x in (("starts", starts), ("goals", goals)):
        if not np.isfinite(x).all():
            raise ValueError(f"{name} contain NaN or infinite values")
    return starts, goals


def build_problem_graph(
    observations: np.ndarray, D: np.ndarray, C: np.ndarray, pairwise: PairwiseFn,
    starts: np.ndarray, goals: np.ndarray, *, d_max: float, c_max: float, endpoint_edges: int = 3,
    relax_cost: bool = True, exclude: Optional[Sequence[int]] = None,
    exclude_edges: Optional[np.ndarray] = None, max_edges: Optional[int] = None,
    avoid: Optional[np.ndarray] = None, avoid_slack: float = 0.0, cost_guard: Optional[float] = 2.0,
    detour: Optional[float] = None, second_opinion: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
    detached: Optional[Sequence[int]] = None, goal_detached: Optional[Sequence[int]] = None,
    attached: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None, passing: Optional[np.ndarray] = None,
    max_leg: Optional[float] = None, long_edges: Optional[np.ndarray] = None, edges: Optional[EdgeList] = None,
) -> ProblemGraph:
    """Attach ``starts`` and ``goals`` to the buffer graph, prune it and relax ``c_max`` where needed.

    The one pipeline from critic matrices to the graph a problem is searched on:
    :func:`attach_endpoints`, :func:`~agents.search.graph.edges.problem_edges`, :func:`problem_edge_mask`,
    then (with ``relax_cost``) :func:`~agents.search.graph.pruning.relax_cost_locally`. ``exclude`` lists
    buffer nodes (``0..N-1``) the graph must not use (e.g. a waypoint an agent failed to reach),
    ``exclude_edges`` (``(E, 2)`` pairs of buffer node ids) edges it must not use (e.g. edges agents
    failed to traverse); ``max_edges`` caps the edges leaving each buffer node towards other buffer
    nodes at its that many shortest ones.
    ``avoid`` (optional) holds observations of places no edge may pass (e.g. agents parked
    there): an edge ``u -> v`` is left out when going through one of them is at most
    ``avoid_slack`` longer, ``D[u, o] + D[o, v] <= D[u, v] + avoid_slack``. An agent whose shortest
    route the cut-off made more than ``cost_guard`` times as costly by the critic as its shortest
    route without it gets that route too (:func:`admit_cheaper_routes`; ``None``: never), and so does one
    whose route the cut-off made more than ``detour`` times as long and costlier at all.
    ``second_opinion(obs_a, obs_b)``: a second critic's predicted steps from ``obs_a[i]`` to ``obs_b[i]``,
    which vouches for such a route's edges that nothing else backs
    (:func:`~agents.search.graph.pruning.trusted_edges`).
    ``detached`` lists buffer nodes no start may link to directly (an agent that failed to reach them
    from where it stood: the critic took that place for one near them), ``goal_detached`` buffer nodes
    that may not link to a goal directly (an agent failed to reach its goal from them); routes may
    still pass them. ``attached``: what :func:`attach_endpoints` returns for these starts and goals,
    where it was computed before (it is the expensive step: the critic scores every new pair), and
    ``passing`` what :func:`passing_edges` returns for them and ``avoid``. ``max_leg``: no edge that
    ``second_opinion`` reads beyond this many steps is admitted; ``long_edges``: what
    :func:`~agents.search.graph.pruning.long_legs` returns for these endpoints and ``max_leg``, where
    computed before (it reads every edge with the second critic); ``edges``: what
    :func:`~agents.search.graph.edges.problem_edges` returns for them, where computed before.
    Every rule works on that list of the edges short enough to exist (:mod:`~agents.search.graph.edges`),
    never on every pair of nodes.
    """
    n = len(observations)
    ex = np.unique(np.asarray([] if exclude is None else exclude, dtype=np.int64))
    if len(ex) and (ex.min() < 0 or ex.max() >= n):
        raise ValueError(f"exclude must hold buffer node ids in [0, {n}), got {ex.tolist()}")
    ee = np.asarray(np.zeros((0, 2)) if exclude_edges is None else exclude_edges, dtype=np.int64).reshape(-1, 2)
    if len(ee) and (ee.min() < 0 or ee.max() >= n):
        raise ValueError(f"exclude_edges must hold pairs of buffer node ids in [0, {n}), got {ee.tolist()}")
    k = len(starts)
    for name, nodes, ends in (("detached", detached, np.arange(n, n + k)),
                              ("goal_detached", goal_detached, np.arange(n + k, n + 2 * k))):
        dt = np.unique(np.asarray([] if nodes is None else nodes, dtype=np.int64))
        if len(dt) and (dt.min() < 0 or dt.max() >= n):
            raise ValueError(f"{name} must hold buffer node ids in [0, {n}), got {dt.tolist()}")
        if len(dt):  # start -> detached node, or goal_detached node -> goal, for every agent
            a, b = np.meshgrid(ends, dt, indexing="ij")
            pairs = np.stack([a, b] if name == "detached" else [b, a], axis=-1).reshape(-1, 2)
            ee = np.concatenate([ee, pairs])
    if attached is None:
        attached = attach_endpoints(observations, D, C, pairwise, starts, goals, d_max)
    D2, C2, obs = attached
    if edges is None:
        edges = problem_edges(EdgeList.short(D, C, d_max), D2, C2, n, d_max)
    if max_leg is not None and math.isfinite(max_leg):
        if second_opinion is None:
            raise ValueError("max_leg needs a second_opinion to read the legs with")
        if long_edges is None:
            long_edges = long_legs(edges, obs, n, second_opinion, max_leg)
        ee = np.concatenate([ee, long_edges])
    if avoid is not None and len(avoid):
        if passing is None:
            passing = passing_edges(D2, obs, pairwise, np.asarray(avoid, dtype=obs.dtype), avoid_slack, d_max)
        ee = np.concatenate([ee, passing])
    allowed = admissible(edges, ex, ee)
    keep = problem_edge_mask(edges, n, c_max, endpoint_edges) & allowed
    if max_edges is not None:
        cap_out_edges(keep, edges, max_edges, n)
    ok, c_used = relax_cost_locally(keep, edges, n, c_max, allowed, relax=relax_cost)
    if cost_guard is not None and math.isfinite(c_max):
        confirm = None if second_opinion is None else (lambda u, v: second_opinion(obs[u], obs[v]))
        admit_cheaper_routes(keep, edges, D2, C2, n, d_max, allowed, factor=cost_guard, detour=detour,
                             confirm=confirm)
    graph = WaypointGraph.from_edges(edges, keep, obs, d_max, c_used)
    return ProblemGraph(obs, D2, C2, graph, n, c_used, ok)


__all__ = ["BorderedMatrix", "NodePairwise", "PairwiseFn", "ProblemGraph", "WaypointGraph", "attach_endpoints",
           "build_problem_graph", "check_endpoints", "check_graph_nodes", "edge_mask", "env_record", "passing_edges",
           "place_distances", "place_passing",
           "problem_edge_mask"]
