"""Waypoints for many agents on the replay-buffer graph: CBS over learned distances.

This is the glue between the critics, the :class:`~agents.search.graph.build.WaypointGraph`, CBS
and the :class:`~agents.search.execution.controller.WaypointController`:

1. the graph's nodes are observations with predicted distances ``D`` and costs ``C`` between every pair
   (:meth:`BufferPlanner.from_agent` computes them once);
2. for a problem, each agent's start and goal observations are attached as extra nodes (their distances and
   costs to every node come from the same critics);
3. edges are kept where ``D < d_max`` and ``C < c_max``; an endpoint always keeps its ``endpoint_edges``
   cheapest edges, so that an agent that starts (or ends) in a costly place is not cut off;
4. a multi-agent solver plans collision-free timed paths (``solver``: ``"auto"`` picks ECBS for up to
   ``AUTO_SEARCH_AGENTS`` agents and prioritised planning with safe intervals above, repairs with large
   neighbourhoods where ECBS runs out of its budget and steps all agents together by priority inheritance
   where prioritised planning gives up, see :class:`BufferPlanner`). Under the default ``"durative"`` time
   model an edge takes ``ceil(D)`` plan steps, so plan time is environment time; two agents conflict when they
   are at nodes whose predicted distance (either direction) is below ``proximity_radius`` (buffer nodes are
   distinct points, so "same node" alone would miss real collisions);
5. :meth:`MultiAgentPlan.agent_plans` turns the paths into per-agent waypoint observations
   and departure times for the controller.

If the cost-pruned graph leaves some agent without any path, the cut-off is relaxed around that agent's start and
goal only (doubling until a path exists; ``MultiAgentPlan.c_max`` reports the largest value used), so the rest of
the graph stays as safe as asked; with ``relax_cost=False`` the plan is ``"infeasible"`` instead. If CBS runs out of
time, a second call with a looser suboptimality bound (``fallback_suboptimality``) usually finds a plan. Every
solver call is budgeted in work (``expansion_limit``, scaled down on dense graphs, ``prioritized_expansions_per_agent``,
``repair_expansions_per_agent``, ``stepper_expansions_per_agent``, ``lacam_expansions_per_agent``) and no wall
clock, so a plan is a function of the problem and the code, the same on an idle and a loaded machine (``time_limit``
adds a wall-clock limit on request).

Only observations and critic outputs enter the planner; positions never do.
"""
from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from .config import OPTIONS, GraphConfig, SearchConfig, preset_for
from .execution.controller import AgentPlan
from .graph.build import (
    NodePairwise,
    PairwiseFn,
    ProblemGraph,
    WaypointGraph,
    attach_endpoints,
    build_problem_graph,
    check_endpoints,
    passing_edges,
    place_distances,
    place_passing,
)
from .graph.edges import EdgeList, problem_edges
from .graph.pruning import long_legs, route_from_predecessors
from .graph.single import lagrangian_risk_path, risk_bounded_path, shortest_path
from .graph.sparsify import two_way_consistent
from .mapf import CBSResult, MapfResult, Proximity
from .mapf.instance import MapfInstance
from .mapf.registry import (
    AUTO_SEARCH_AGENTS,
    SolverConfig,
    solve,
)
from .mapf.registry import SOLVERS as REGISTERED_SOLVERS
from .waypoints import waypoints_from_paths

#: The planner's multi-agent solvers (``"auto"`` chooses by the number of agents).
SOLVERS = tuple(REGISTERED_SOLVERS)
#: edge-steps per node (the sum of the problem graph's edge durations over its nodes) up to which one
#: CBS / ECBS call may make ``expansion_limit`` expansions; on a denser graph, where an expansion scans
#: more edges, the call may make proportionally fewer (1000-node graphs: CentralObstacle about 290,
#: the apartments up to about 480, CenterDot's small room about 2,200)
REFERENCE_EDGE_STEPS = 600
#: buffer nodes up to which ``prioritized_expansions_per_agent`` holds as given; on a graph of more
#: nodes, where one agent's safe-interval search explores more of them, it grows in proportion
REFERENCE_BUFFER_NODES = 1000
#: the cost :meth:`BufferPlanner.from_agent` with a ``bound`` gives the pairs it never read (never an edge)
UNREAD_COST = 1e9
#: places to avoid (parked agents' observations) whose distances and passing edges a planner keeps per
#: ``d_max``; past it, it starts over (1000 agents' goals on a 4000-node buffer: about 32 MB)
_KEPT_PLACES = 4096


def _same_rows(x: Any) -> Optional[Tuple[int, int]]:
    """The first two indices whose rows of ``x`` are equal, or ``None``."""
    rows = np.asarray(x)
    if rows.ndim == 0 or len(rows) < 2:
        return None
    _, first, inverse = np.unique(rows.reshape(len(rows), -1), axis=0, return_index=True, return_inverse=True)
    inverse = np.asarray(inverse).reshape(-1)
    for i, k in enumerate(inverse):
        if first[k] != i:
            return int(first[k]), i
    return None


#: ``with_options``' marker of an argument left as it is
_KEEP: Any = object()


def _vary(graph: GraphConfig, solver: SolverConfig, changes: Dict[str, Any]) -> Tuple[GraphConfig, SolverConfig]:
    """``graph`` and ``solver`` with ``changes`` (option names of their fields) applied; a name of
    another part, or none, raises ``ValueError``."""
    if not changes:
        return graph, solver
    other = sorted(k for k in changes if OPTIONS.get(k, ("?",))[0] not in ("graph", "solver"))
    if other:
        names = sorted(k for k, (part, _) in OPTIONS.items() if part in ("graph", "solver"))
        raise ValueError(f"{other} are not options of the planner's graph or solver; those are {names}")
    config = SearchConfig(graph=graph, solver=solver).updated(**changes)
    return config.graph, config.solver


@dataclass
class MultiAgentPlan:
    """Per-agent waypoints with departure times, from one CBS call.

    Attributes:
        status: the CBS status (``"optimal"``, ``"suboptimal"``, ``"timeout"``,
            ``"infeasible"``).
        nodes: per agent, the node ids it visits in order, start included, goal excluded
            (ids of the problem graph: ``0..N-1`` buffer nodes, then starts, then goals).
        depart_times: per agent, the plan time at which it leaves each node of ``nodes``.
        node_arrivals: per agent, the plan time at which it gets to each node of ``nodes``.
        arrival_times: per agent, the plan time of its final arrival at its goal.
        soc: sum of arrival times; ``makespan``: the latest one.
        c_max: the cost cut-off used (larger than asked if it had to be relaxed).
        planning_time: seconds spent attaching endpoints, pruning and searching.
        cbs: the full CBS result (paths, statistics).
        message: why planning ended as it did.
        predicted_cost: per agent, the predicted cost of its route (sum over its edges).
        problem: the problem graph the plan was made on (node observations, dense ``D`` and
            ``C``, the pruned graph), for execution, plots and inspection.
        solver: which solver made the plan (``"cbs"``, ``"prioritized"``, ``"lns"``, ``"pibt"``,
            ``"lacam"`` or ``"single"``; ``""`` when none ran).
    """

    status: str
    nodes: List[List[int]] = field(default_factory=list)
    depart_times: List[List[int]] = field(default_factory=list)
    node_arrivals: List[List[int]] = field(default_factory=list)
    arrival_times: List[int] = field(default_factory=list)
    soc: Optional[int] = None
    makespan: Optional[int] = None
    c_max: float = math.inf
    planning_time: float = 0.0
    cbs: Optional[CBSResult] = None
    message: str = ""
    predicted_cost: List[float] = field(default_factory=list)
    problem: Optional[ProblemGraph] = field(default=None, repr=False)
    solver: str = ""

    @property
    def solved(self) -> bool:
        return bool(self.nodes)

    @property
    def observations(self) -> np.ndarray:
        """Observations of the problem graph's nodes, indexed by node id."""
        if self.problem is None:
            raise ValueError(f"this plan has no problem graph (status {self.status!r})")
        return self.problem.observations

    def waypoint_observations(self, agent: int) -> np.ndarray:
        """The observations agent ``agent`` visits in order (its start first, its goal excluded)."""
        return self.observations[np.asarray(self.nodes[agent], dtype=np.int64)]

    def agent_plans(self, names: Optional[Sequence[str]] = None, hold: str = "all") -> Dict[str, AgentPlan]:
        """Controller plans: waypoint observations (start node included) and departure times.

        ``hold`` says where an agent that is early must wait for its planned departure time:
        ``"all"`` (every waypoint: plan time is environment time) or ``"waits"`` (only where
        the plan itself waits, i.e. where CBS delayed the agent to let another one pass; edge
        durations are pessimistic predictions, so holding everywhere mostly means standing
        still, which costs where the cost field is not zero).

        Args:
            names: agent names (default ``agent_0``, ...), in the order of the planned agents.
            hold: ``"all"`` or ``"waits"`` (above).
        """
        if not self.solved:
            raise ValueError(f"no plan to execute: planning ended with status {self.status!r} ({self.message})")
        k = len(self.nodes)
        names = list(names) if names is not None else [f"agent_{i}" for i in range(k)]
        if len(names) != k:
            raise ValueError(f"{k} planned agents but {len(names)} names")
        if hold not in ("all", "waits"):
            raise ValueError(f"hold must be 'all' or 'waits', got {hold!r}")
        obs = self.observations
        assert self.problem is not None  # checked by ``observations``
        goals = obs[self.problem.goal_ids]
        out = {}
        for i in range(k):
            depart = list(self.depart_times[i])
            if hold == "waits":
                depart = [d if d > a else 0 for d, a in zip(depart, self.node_arrivals[i])]
            out[names[i]] = AgentPlan(waypoints=obs[np.asarray(self.nodes[i], dtype=np.int64)],
                                      goal=np.asarray(goals[i]), depart_times=depart, starts_at_first=True)
        return out


class BufferPlanner:
    """Plans waypoints for several agents (CBS / ECBS, or prioritised planning) on a graph of observations.

    Args:
        observations: the graph's node observations, ``(N, ...)``.
        D, C: predicted distance and cost between every pair of nodes, ``(N, N)``.
        pairwise: ``pairwise(obs_a, obs_b) -> (D, C)`` from the same critics, used to attach start and goal
            observations (e.g. ``agent.pairwise``).
        graph: which edges a problem keeps, when agents conflict, how long an edge takes
            (:class:`~agents.search.config.GraphConfig`: ``d_max``, ``c_max``, ``proximity_radius``, ...).
        solver: the multi-agent solver and its budgets (:class:`~agents.search.mapf.registry.SolverConfig`):
            ``"auto"`` (default) runs CBS / ECBS for up to ``AUTO_SEARCH_AGENTS`` (20) agents, then the
            large-neighbourhood repair if CBS runs out of its budget, and prioritised planning with safe
            intervals above, then the priority inheritance stepper if that gives up; every budget is counted in
            work, not seconds, and scaled to the graph (:meth:`work_scale`, :meth:`size_scale`), so the same
            problem gives the same plan on an idle and a loaded machine.
        second_opinion: ``(obs_a, obs_b) -> steps`` of a second critic, pair by pair (e.g. the driving agent's
            ``distance``), that vouches for the edges of a route the cost guard gives back where nothing else does
            (:func:`~agents.search.graph.pruning.trusted_edges`) and reads legs for ``graph.max_leg``; ``None``: none.
            Not saved with the configs.

    :meth:`with_options` varies the configs by option name (``planner.with_options(c_max=0.25)``).
    """

    def __init__(
        self,
        observations: np.ndarray,
        D: np.ndarray,
        C: np.ndarray,
        pairwise: PairwiseFn,
        graph: Optional[GraphConfig] = None,
        solver: Optional[SolverConfig] = None,
        *,
        second_opinion: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
    ) -> None:
        self.observations = np.asarray(observations)
        n = len(self.observations)
        self.D = np.asarray(D, dtype=np.float64)
        self.C = np.asarray(C, dtype=np.float64)
        for name, m in (("D", self.D), ("C", self.C)):
            if m.shape != (n, n):
                raise ValueError(f"{name} must have shape ({n}, {n}) for {n} observations, got {m.shape}")
            if not np.isfinite(m).all() or (m < 0).any():
                raise ValueError(f"{name} must be finite and non-negative")
        graph = GraphConfig() if graph is None else graph
        solver = SolverConfig() if solver is None else solver
        if not isinstance(graph, GraphConfig) or not isinstance(solver, SolverConfig):
            raise TypeError(f"graph and solver must be a GraphConfig and a SolverConfig, got "
                            f"{type(graph).__name__} and {type(solver).__name__} (planner.with_options(...) "
                            "varies them by option name)")
        max_leg = graph.max_leg
        if max_leg is not None and math.isfinite(max_leg) and second_opinion is None:
            raise ValueError(f"max_leg needs a second_opinion to read legs with, got max_leg={max_leg!r}")
        self.pairwise = pairwise
        #: the graph's settings and the solver's
        self.graph = graph
        self.solver_config = solver
        self.second_opinion = second_opinion
        #: the buffer's long legs by (d_max, max_leg), shared by the planners with_options makes
        self._long_legs: Dict[Tuple[float, float], np.ndarray] = {}
        #: the long legs of the last endpoints attached (the buffer's and theirs)
        self._long: Optional[Tuple[Tuple[Any, ...], np.ndarray]] = None
        self._buffer_graph: Optional[WaypointGraph] = None
        #: the last endpoints attached and edges found to pass places to avoid (a replan tries graphs from one place)
        self._attached: Optional[Tuple[Tuple[Any, ...], Tuple[np.ndarray, np.ndarray, np.ndarray]]] = None
        self._passing: Optional[Tuple[Tuple[Any, ...], np.ndarray]] = None
        #: the buffer nodes' distances to and from each place to avoid met so far, by d_max and place (they
        #: outlive the endpoints and the set of places: a parked agent's stay scored once)
        #: and, by slack, the buffer's edges that pass each of them (:func:`place_passing`)
        self._places: Dict[float, Dict[bytes, Tuple[np.ndarray, np.ndarray, Dict[float, np.ndarray]]]] = {}
        #: the buffer's edges shorter than d_max, by d_max (shared by the planners over the same matrices), and
        #: the candidate edges of the last endpoints attached
        self._short: Dict[float, EdgeList] = {}
        self._edges: Optional[EdgeList] = None
        #: the matrices of the last endpoints attached, written over for the next ones of as many agents
        #: where nothing refers to them any more (:meth:`_scratch_for`)
        self._scratch: Optional[Tuple[np.ndarray, np.ndarray]] = None

    @property
    def buffer_graph(self) -> WaypointGraph:
        """The buffer nodes' graph pruned at ``d_max`` only (no cost cut-off, no endpoints): the
        graph SoRB searches and the evaluation measures problem difficulty on."""
        if self._buffer_graph is None:
            self._buffer_graph = WaypointGraph.from_matrices(self.D, self.C, d_max=self.graph.d_max,
                                                             observations=self.observations)
        return self._buffer_graph

    @classmethod
    def from_agent(cls, agent, observations: np.ndarray, aggregate: str = "max",
                   bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
                   graph: Optional[GraphConfig] = None, solver: Union[SolverConfig, str, None] = None, *,
                   second_opinion: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
                   **changes: Any) -> "BufferPlanner":
        """Compute ``D`` and ``C`` with ``agent.pairwise`` (ensemble aggregated by ``aggregate``).

        ``graph`` defaults to the graph part of :func:`~agents.search.config.preset_for` ``agent``;
        ``solver`` is a :class:`~agents.search.mapf.registry.SolverConfig` or a solver's name;
        ``changes`` vary both by option name (:meth:`with_options`), e.g.
        ``from_agent(agent, obs, c_max=0.25)``.

        ``bound(obs_a, obs_b)``: a lower bound of the distance in steps that needs no critic, such
        as the environment's ``min_steps`` (vector observations). Then only the pairs it puts
        below ``d_max`` are read by the critics, here and when starts and goals are attached (see
        :class:`~agents.search.graph.build.NodePairwise`): on a large map, where most pairs are far
        apart, a graph of thousands of nodes takes seconds instead of minutes. ``D`` and ``C`` are
        then exact only below ``d_max`` (all the planner reads); a pair the bound rules out keeps
        the bound as its distance and :data:`UNREAD_COST` as its cost."""
        graph = preset_for(agent).graph if graph is None else graph
        if isinstance(solver, str):
            solver, changes = SolverConfig(), {"solver": solver, **changes}
        graph, solver = _vary(graph, solver or SolverConfig(), changes)
        obs = np.asarray(observations)
        pairwise = NodePairwise(agent, obs, aggregate, bound=bound)  # the nodes are encoded once
        if bound is None:
            D, C = pairwise(obs, obs)
        else:
            D, C = pairwise.within(obs, obs, graph.d_max)
            C = np.where(np.isfinite(C), C, UNREAD_COST)
        return cls(obs, D, C, pairwise, graph, solver, second_opinion=second_opinion)

    def config(self) -> Dict[str, Any]:
        """The graph's and the solver's configs as JSON-ready dicts (``{"graph": ..., "solver": ...}``, the
        parts of :meth:`~agents.search.config.SearchConfig.to_dict`)."""
        return {"graph": dataclasses.asdict(self.graph), "solver": dataclasses.asdict(self.solver_config)}

    def sparsified(self, tau: float, order: Optional[np.ndarray] = None) -> Tuple["BufferPlanner", np.ndarray]:
        """A planner over the nodes kept by two-way consistency merging at ``tau`` steps
        (:func:`~agents.search.graph.sparsify.two_way_consistent`), and the kept node indices."""
        kept = two_way_consistent(self.D, tau, order)
        obs = self.observations[kept]
        pairwise = self.pairwise
        if isinstance(pairwise, NodePairwise):  # it caches the codes of its own nodes
            pairwise = NodePairwise(pairwise.model, obs, pairwise.aggregate)
        ix = np.ix_(kept, kept)
        return BufferPlanner(obs, self.D[ix], self.C[ix], pairwise, self.graph, self.solver_config,
                             second_opinion=self.second_opinion), kept

    def with_configs(self, graph: GraphConfig, solver: SolverConfig) -> "BufferPlanner":
        """A planner over the same nodes, matrices and second opinion with these configs."""
        out = BufferPlanner(self.observations, self.D, self.C, self.pairwise, graph, solver,
                            second_opinion=self.second_opinion)
        out._long_legs, out._short, out._places = self._long_legs, self._short, self._places
        return out

    def with_options(self, second_opinion: Any = _KEEP, **changes: Any) -> "BufferPlanner":
        """A planner over the same nodes and matrices with options of its graph and solver changed by
        name (:data:`~agents.search.config.OPTIONS`, e.g. ``c_max=0.25``, ``solver="lns"``), and
        optionally another ``second_opinion``."""
        graph, solver = _vary(self.graph, self.solver_config, changes)
        opinion = self.second_opinion if second_opinion is _KEEP else second_opinion
        out = BufferPlanner(self.observations, self.D, self.C, self.pairwise, graph, solver, second_opinion=opinion)
        out._short, out._places = self._short, self._places
        if out.second_opinion is self.second_opinion:
            out._long_legs = self._long_legs
        return out

    # ------------------------------------------------------------------ problem graph
    def problem_graph(self, starts: np.ndarray, goals: np.ndarray, exclude: Optional[Sequence[int]] = None,
                      exclude_edges: Optional[np.ndarray] = None, avoid: Optional[np.ndarray] = None,
                      detached: Optional[Sequence[int]] = None,
                      goal_detached: Optional[Sequence[int]] = None) -> ProblemGraph:
        """The graph a problem is searched on: buffer nodes plus the agents' start and goal
        observations, pruned with this planner's cut-offs (see
        :func:`~agents.search.graph.build.build_problem_graph`; edges that pass a place of ``avoid`` go
        within the proximity radius). Two agents with the same goal are refused (``ValueError``)."""
        starts, goals = check_endpoints(self.observations, starts, goals)
        same = _same_rows(goals)
        if same is not None:
            raise ValueError(f"agents {same[0]} and {same[1]} have the same goal: no plan brings both there (every "
                             "agent needs a place of its own)")
        key = (starts.shape, starts.tobytes(), goals.tobytes())
        g = self.graph
        if self._attached is None or self._attached[0] != key:
            # drop what refers to the last endpoints' matrices
            self._attached = self._passing = self._long = self._edges = None
            size = len(self.observations) + 2 * len(starts)
            D2, C2, obs = attach_endpoints(self.observations, self.D, self.C, self.pairwise, starts, goals,
                                           self.graph.d_max, out=self._scratch_for(size))
            self._scratch = (D2, C2)
            self._attached = (key, (D2, C2, obs))
            self._edges = problem_edges(self._short_edges(), D2, C2, len(self.observations), g.d_max)
        passing = None
        if avoid is not None and len(avoid):
            at = np.asarray(avoid, dtype=self.observations.dtype)  # where parked agents stand, say
            k2 = (key, at.shape, at.tobytes())
            if self._passing is None or self._passing[0] != k2:
                D2, _, obs = self._attached[1]
                slack = float(g.proximity_radius or 0)
                known, pairs = self._avoided_places(at, slack)
                self._passing = (k2, passing_edges(D2, obs, self.pairwise, at, slack, g.d_max, known=known,
                                                   known_pairs=pairs))
            passing = self._passing[1]
        return build_problem_graph(self.observations, self.D, self.C, self.pairwise, starts, goals,
                                   d_max=g.d_max, c_max=g.c_max, endpoint_edges=g.endpoint_edges,
                                   relax_cost=g.relax_cost, exclude=exclude, exclude_edges=exclude_edges,
                                   max_edges=g.max_edges, avoid=avoid, avoid_slack=g.proximity_radius or 0.0,
                                   cost_guard=g.cost_guard, detour=g.detour,
                                   second_opinion=self.second_opinion, detached=detached,
                                   goal_detached=goal_detached, attached=self._attached[1], passing=passing,
                                   max_leg=g.max_leg, long_edges=self._long_edges(key), edges=self._edges)

    def _avoided_places(self, at: np.ndarray, slack: float) -> Tuple[Tuple[np.ndarray, np.ndarray], List[np.ndarray]]:
        """What the buffer knows of the places ``at``: :func:`~agents.search.graph.build.place_distances` of
        the buffer to them, ``(N, P)`` and ``(P, N)``, and per place the buffer's edges that pass it
        (:func:`~agents.search.graph.build.place_passing`). Each place is scored once per ``d_max``, on its
        own, and kept with its edges by ``slack`` (at most :data:`_KEPT_PLACES` places), so that what a
        replan reads does not depend on the replans before it."""
        d_max = self.graph.d_max
        kept = self._places.setdefault(d_max, {})
        keys = [row.tobytes() for row in at]
        first: Dict[bytes, int] = {}  # each place's first row in ``at``
        for i, k in enumerate(keys):
            first.setdefault(k, i)
        if len(kept) + sum(k not in kept for k in first) > _KEPT_PLACES:
            kept.clear()
        for k, i in first.items():
            if k not in kept:  # one at a time: a place's distances do not depend on which others were new with it
                to_place, from_place = place_distances(self.pairwise, self.observations, at[i:i + 1], d_max)
                kept[k] = (to_place[:, 0], from_place[0], {})
        records = [kept[k] for k in keys]
        for to_place, from_place, passing in records:
            if slack not in passing:
                passing[slack] = place_passing(self.D, to_place, from_place, slack, d_max)
        known = np.stack([r[0] for r in records], axis=1), np.stack([r[1] for r in records], axis=0)
        return known, [r[2][slack] for r in records]

    def _short_edges(self) -> EdgeList:
        """The buffer's edges shorter than ``d_max`` (found once per ``d_max``)."""
        d_max = self.graph.d_max
        if d_max not in self._short:
            self._short[d_max] = EdgeList.short(self.D, self.C, d_max)
        return self._short[d_max]

    def _scratch_for(self, size: int) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """The last attached matrices, if they are ``(size, size)`` and nothing but this planner refers to
        them (no problem graph, plan or view of them is alive): their buffer blocks are written already,
        so attaching new endpoints of as many agents writes only the borders."""
        if self._scratch is None or self._scratch[0].shape != (size, size):
            return None
        d2, c2 = self._scratch
        # references to each: the scratch tuple's, the local name's and getrefcount's own argument
        if sys.getrefcount(d2) > 3 or sys.getrefcount(c2) > 3:
            self._scratch = None  # still in use: the next attach makes new ones
            return None
        return self._scratch

    def _long_edges(self, key: Tuple[Any, ...]) -> Optional[np.ndarray]:
        """The edges of the attached problem (``key``: its endpoints) that ``second_opinion`` reads beyond
        ``max_leg``: the buffer's are read once per graph, the endpoints' once per endpoints."""
        if self.graph.max_leg is None or not math.isfinite(self.graph.max_leg):
            return None
        read, n = self.second_opinion, len(self.observations)
        assert read is not None and self._attached is not None  # checked in __init__; attached by the caller
        d_max, max_leg = self.graph.d_max, self.graph.max_leg
        if (d_max, max_leg) not in self._long_legs:
            self._long_legs[(d_max, max_leg)] = long_legs(self._short_edges(), self.observations, n, read, max_leg)
        if self._long is None or self._long[0] != key:
            _, _, obs = self._attached[1]
            assert self._edges is not None  # made with the attached matrices
            self._long = (key, long_legs(self._edges, obs, n, read, max_leg, self._long_legs[(d_max, max_leg)]))
        return self._long[1]

    def plan(self, starts: np.ndarray, goals: np.ndarray, budget: Optional[float] = None,
             exclude: Optional[Sequence[int]] = None, exclude_edges: Optional[np.ndarray] = None,
             avoid: Optional[np.ndarray] = None, detached: Optional[Sequence[int]] = None,
             goal_detached: Optional[Sequence[int]] = None) -> MultiAgentPlan:
        """Plan for agents starting at observations ``starts[i]`` and going to ``goals[i]``.

        ``budget`` (optional) bounds each agent's total predicted cost: every agent's route is
        first the shortest one within the budget (an exact resource-constrained shortest path,
        or a Lagrangian one within the budget if the exact search exceeds ``budget_labels``;
        the cheapest route if none fits), and CBS then times the agents on the graph induced by
        the nodes of those routes.

        ``exclude`` (optional) lists buffer nodes (ids ``0..N-1``) the plan must not use, e.g.
        a waypoint an agent failed to reach when it replans; ``exclude_edges`` (optional, ``(E, 2)``)
        pairs of buffer nodes whose edge the plan must not use, e.g. edges agents failed to traverse;
        ``avoid`` (optional) observations of places no edge may pass within the proximity radius,
        e.g. where agents are parked; ``detached`` (optional) buffer nodes no start may link to
        directly, e.g. those an agent failed to reach from where it stood, and ``goal_detached``
        (optional) buffer nodes that may not link to a goal directly, e.g. those an agent failed to
        reach its goal from.
        """
        t0 = time.perf_counter()
        problem = self.problem_graph(starts, goals, exclude, exclude_edges, avoid, detached, goal_detached)
        k = problem.n_agents
        s_ids, g_ids = problem.start_ids, problem.goal_ids
        D, C, c_max, graph = problem.D, problem.C, problem.c_max, problem.graph
        if not problem.connected.all():
            bad = [int(i) for i in np.flatnonzero(~problem.connected)]
            return MultiAgentPlan("infeasible", c_max=c_max, planning_time=time.perf_counter() - t0, problem=problem,
                                  message=f"agents {bad} have no path from start to goal in the pruned graph")
        if budget is not None:
            graph = self._budget_subgraph(graph, s_ids, g_ids, float(budget))
        durations = graph.distance.copy()
        if self.graph.time_model == "durative":  # an edge takes ceil(D) steps
            durations.data = np.maximum(np.ceil(durations.data - 1e-9), 1.0)
        else:
            durations.data = np.ones_like(durations.data)
        if k == 1:  # one agent has nobody to conflict with: CBS's answer is the shortest timed path
            res, used = self._single_agent_path(durations, s_ids[0], g_ids[0]), "single"
        else:
            res, used = self._solve(durations, s_ids, g_ids, D)
        out = MultiAgentPlan(res.status, soc=res.soc, makespan=res.makespan, c_max=c_max, cbs=res,
                             message=res.message, problem=problem, solver=used)
        if res.solved and res.paths is not None:
            out.nodes, out.depart_times, out.node_arrivals, out.arrival_times = waypoints_from_paths(res.paths)
            out.predicted_cost = [self._route_cost(C, nodes + [g]) for nodes, g in zip(out.nodes, g_ids)]
        out.planning_time = time.perf_counter() - t0
        return out

    def _solve(self, durations: sparse.csr_matrix, s_ids, g_ids, D: np.ndarray) -> Tuple[MapfResult, str]:
        """Run the solver ``solver_config`` names (:func:`~agents.search.mapf.registry.solve`, ``"auto"``: the
        cascade that picks by the number of agents); ``(result, solver used)``."""
        k = len(s_ids)
        prox = self.problem_proximity(D, k)
        inst = MapfInstance(durations, s_ids, g_ids, time_model=self.graph.time_model, proximity=prox)
        # every budget in the same work on dense graphs; prioritised planning's grows with the graph's size
        res = solve(inst, self.solver_config, scale=self.work_scale(durations), size_scale=self.size_scale())
        return res, res.solver

    @staticmethod
    def work_scale(durations: sparse.csr_matrix) -> float:
        """The share of its expansion budgets a solver call may spend on a problem graph with these edge
        durations: 1 up to ``REFERENCE_EDGE_STEPS`` edge-steps per node, less on denser graphs, where
        an expansion scans proportionally more edges."""
        density = float(durations.data.sum()) / max(1, durations.shape[0])
        return 1.0 if density <= REFERENCE_EDGE_STEPS else REFERENCE_EDGE_STEPS / density

    def size_scale(self) -> float:
        """The factor of the prioritised planning budget for this graph's size: 1 up to
        ``REFERENCE_BUFFER_NODES`` buffer nodes, their number over it above."""
        return max(1.0, len(self.observations) / REFERENCE_BUFFER_NODES)

    def _single_agent_path(self, durations: sparse.csr_matrix, s: int, g: int) -> MapfResult:
        """The optimal timed path of a lone agent (Dijkstra over edge durations; solver ``"single"``, no work
        counted)."""
        dist, pred = dijkstra(durations, directed=True, indices=s, return_predecessors=True)
        if not np.isfinite(dist[g]):
            return MapfResult("infeasible", message="no path from start to goal", time_model=self.graph.time_model,
                              solver="single")
        nodes = route_from_predecessors(pred, s, g)
        path = [(int(v), int(round(dist[v]))) for v in nodes]
        t = int(round(dist[g]))
        return MapfResult("optimal", paths=[path], soc=t, makespan=t, lower_bound=t,
                          message="a single agent: shortest path", time_model=self.graph.time_model, solver="single")

    def problem_proximity(self, D: np.ndarray, k: int) -> Optional[Proximity]:
        """The proximity conflicts of a problem graph with distances ``D`` and ``k`` agents
        (``None`` without a proximity radius): nodes closer than the radius; starts among
        themselves (and goals among themselves) are exempt: agents placed or parked side by side
        by the environment are not a planning conflict, and otherwise such a problem could never
        be solved."""
        if not self.graph.proximity_radius:
            return None
        n = len(self.observations)
        return Proximity(D, self.graph.proximity_radius, exempt=((n, n + k), (n + k, n + 2 * k)))

    @staticmethod
    def _route_cost(C: np.ndarray, nodes: List[int]) -> float:
        a, b = np.array(nodes[:-1], dtype=np.int64), np.array(nodes[1:], dtype=np.int64)
        return float(C[a, b].sum()) if len(a) else 0.0

    def _budget_subgraph(self, graph: WaypointGraph, s_ids, g_ids, budget: float):
        """The graph induced by the nodes of every agent's shortest route within ``budget``."""
        nodes = set()
        for s, g in zip(s_ids, g_ids):
            p = risk_bounded_path(graph, s, g, budget, max_labels=self.graph.budget_labels)
            if p.status == "limit":  # the exact search ran long: a fast path within the budget
                p = lagrangian_risk_path(graph, s, g, budget)
            if not p.found:
                p = shortest_path(graph, s, g, objective="cost")
            nodes.update(p.nodes)
        idx = np.array(sorted(nodes), dtype=np.int64)
        mask = np.zeros(graph.n_nodes, dtype=bool)
        mask[idx] = True
        d = graph.distance.tocoo()
        keep = mask[d.row] & mask[d.col]
        n = graph.n_nodes
        cdata = graph.cost_data()
        dist = sparse.csr_matrix((d.data[keep], (d.row[keep], d.col[keep])), shape=(n, n))
        cost = sparse.csr_matrix((cdata[keep], (d.row[keep], d.col[keep])), shape=(n, n))
        return WaypointGraph(dist, cost, graph.observations, graph.d_max, graph.c_max)


__all__ = ["AUTO_SEARCH_AGENTS", "BufferPlanner", "MultiAgentPlan", "PairwiseFn", "SOLVERS"]
