"""Waypoints for many agents on the replay-buffer graph: CBS over learned distances.

This is the glue between the critics, the :class:`~agents.search.graph.WaypointGraph`, CBS
and the :class:`~agents.search.controller.WaypointController`:

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

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from .controller import AgentPlan
from .graph import (
    NodePairwise,
    PairwiseFn,
    ProblemGraph,
    WaypointGraph,
    attach_endpoints,
    build_problem_graph,
    check_endpoints,
    passing_edges,
)
from .mapf import CBSResult, MapfResult, Proximity
from .mapf.instance import MapfInstance
from .mapf.registry import (
    AUTO_SEARCH_AGENTS,
    DEFAULT_CBS_EXPANSION_LIMIT,
    DEFAULT_LACAM_EXPANSIONS_PER_AGENT,
    DEFAULT_PRIORITIZED_EXPANSIONS_PER_AGENT,
    DEFAULT_REPAIR_EXPANSIONS_PER_AGENT,
    DEFAULT_STEPPER_EXPANSIONS_PER_AGENT,
    SolverConfig,
    solve,
)
from .mapf.registry import SOLVERS as REGISTERED_SOLVERS
from .models import default_detour
from .pruning import long_legs, route_from_predecessors
from .single import lagrangian_risk_path, risk_bounded_path, shortest_path
from .sparsify import two_way_consistent
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
#: default ``d_max`` (predicted steps): edges of the graph are shorter
DEFAULT_D_MAX = 7.0
#: the cost :meth:`BufferPlanner.from_agent` with a ``bound`` gives the pairs it never read (never an edge)
UNREAD_COST = 1e9


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
        d_max: keep edges with ``D < d_max`` (default 7, the paper's value).
        c_max: keep edges with ``C < c_max`` (``inf``: distance pruning only, as in SoRB).
        endpoint_edges: every start keeps at least its this many cheapest outgoing edges and every goal its cheapest
            incoming ones, whatever ``c_max``.
        proximity_radius: agents conflict at nodes closer than this (predicted steps, either direction); ``None``
            checks only same-node conflicts.
        time_model: ``"durative"`` (edges take ``ceil(D)`` steps) or ``"unit"`` (the paper's one step per edge).
        suboptimality: 1 for optimal CBS, ``w > 1`` for ECBS within ``w`` of optimal (default 1.1: optimal CBS is
            often too slow with 20 agents on a dense buffer graph).
        solver: ``"cbs"`` (CBS, or ECBS with ``suboptimality > 1``), ``"prioritized"`` (prioritised planning with
            safe-interval path planning, :func:`~agents.search.mapf.prioritized.solve_prioritized`: agents one after
            another, each on its earliest path around the earlier ones; fast with hundreds of agents, cost not
            bounded, can fail where a plan exists), ``"lns"`` (large-neighbourhood repair,
            :func:`~agents.search.mapf.lns.solve_lns`: a prioritised plan in which an agent that finds no
            conflict-free path takes the least conflicting one, then small groups of agents re-planned until no
            conflict is left; solves crowds where prioritised planning gives up), ``"pibt"`` (the priority
            inheritance stepper, :func:`~agents.search.mapf.pibt.solve_pibt`: all agents step together, an agent in
            the way of a more urgent one is pushed off its node; solves the crowds of the most agents a
            problem on the graph places, with long makespans), ``"lacam"`` (the search over the agents' joint
            configurations with that stepping as its successor generator,
            :func:`~agents.search.mapf.lacam.solve_lacam`: complete, so an impossible problem small enough to
            exhaust is reported ``"infeasible"``; its plan improves with its budget,
            ``lacam_expansions_per_agent``) or ``"auto"`` (default): ``"cbs"`` for up to
            ``AUTO_SEARCH_AGENTS`` (20) agents, then ``"lns"`` if CBS / ECBS runs out of its budget (status
            ``"timeout"``), else ``"prioritized"``, then ``"pibt"`` if prioritised planning gives up (status
            ``"timeout"``; not the repair: where prioritised planning gives up on the 1000-node buffer graph, the
            repair spent its whole budget, about a minute, and solved none).
        expansion_limit: the work budget of one CBS / ECBS call, in low-level expansions (space-time states;
            ``None``: none), on graphs of up to ``REFERENCE_EDGE_STEPS`` edge-steps per node; on denser graphs
            this budget and the three below are proportionally smaller (:meth:`work_scale`), so that the edges a
            call scans stay within the same budget. Counted in work, not seconds, so the same problem gives the
            same plan (or the same timeout) on an idle and a loaded machine.
        prioritized_expansions_per_agent: the work budget of prioritised planning, in safe-interval expansions over
            all agents and restarts, per agent (``None``: none), on graphs of up to ``REFERENCE_BUFFER_NODES`` (1000)
            buffer nodes; on a graph of more nodes it grows in proportion (:meth:`size_scale`).
        repair_expansions_per_agent: the work budget of the large-neighbourhood repair, in search expansions over
            the initial plan and the repair, per agent (``None``: none).
        repair_seed: seeds the repair's choice of the agents re-planned together, and the configuration search's
            tie-breaks (an integer; the same seed, the same plan).
        stepper_expansions_per_agent: the work budget of the priority inheritance stepper, in candidate moves
            examined, per agent (``None``: none).
        lacam_expansions_per_agent: the work budget of the configuration search (``solver="lacam"``), per agent
            (``None``: none, then it runs until its plan is proven optimal): candidate moves, constraints and
            repaired edges; what is left after the first plan goes to improving it.
        time_limit: wall-clock seconds for one solver call (``None``, the default: no wall-clock limit, the budgets
            in work alone end a call). A limit in seconds makes plans depend on the machine's load; either ends
            the call with status ``"timeout"`` (the message says which).
        relax_cost: relax ``c_max`` locally until every agent has a path (otherwise report infeasible); see
            :func:`~agents.search.pruning.relax_cost_locally`.
        fallback_suboptimality: if CBS runs out of time, one more try with this (larger) suboptimality bound and the
            same time limit (``None``: no second try).
        budget_labels: label limit of the exact risk-bounded search of :meth:`plan`'s budget mode; past it, a
            Lagrangian path within the budget is used instead.
        max_edges: keep at most this many edges out of each buffer node towards other buffer nodes (its shortest
            ones; ``None``: every edge under the cut-offs). Fewer long edges, fewer edges a critic can misjudge (see
            also :meth:`sparsified`).
        cost_guard: where ``c_max`` leaves an agent only a detour the critic predicts more than this many times as
            costly as its shortest route without the cut-off, that route is admitted too
            (:func:`~agents.search.pruning.admit_cheaper_routes`): no agent is sent the long way round to a far
            higher cost (``None``: off).
        detour: where ``c_max`` leaves an agent only a route more than this many times as long as its shortest route
            without the cut-off, and costlier by the critic at all, that route is admitted too: longer and costlier
            buys nothing (``None``: off, the default; :meth:`from_agent` turns it on for agents of panoramas,
            :func:`~agents.search.models.default_detour`).
        spread_routes: :class:`~agents.search.mapf.CBSSolver`'s ``spread``: of routes equal in cost and conflicts,
            those through fewer nodes of (``"routes"``) or near (``"near"``) other routes; fewer plan-order dependencies
            (``"off"`` by default: on panoramas it lost runs or little cost; see the Planning page of the docs).
        second_opinion: ``(obs_a, obs_b) -> steps`` of a second critic, pair by pair (e.g. the driving agent's
            ``distance``), that vouches for the edges of a route the cost guard gives back where nothing else does
            (:func:`~agents.search.pruning.trusted_edges`; ``None``: none). Not saved with the options.
        max_leg: no edge that ``second_opinion`` reads beyond this many steps is planned, nor admitted past the cost
            cut-off (:func:`~agents.search.pruning.long_legs`; needs ``second_opinion``; ``None`` or ``inf``: off). A
            :class:`~agents.search.policy.SearchPolicy` with a fallback sets it to the controller's
            ``fallback_beyond`` where the second opinion is the driver's critic (such a leg would go to the
            fallback policy at once), unless it is set.
    """

    def __init__(
        self,
        observations: np.ndarray,
        D: np.ndarray,
        C: np.ndarray,
        pairwise: PairwiseFn,
        *,
        d_max: float = DEFAULT_D_MAX,
        c_max: float = math.inf,
        endpoint_edges: int = 3,
        proximity_radius: Optional[float] = 1.5,
        time_model: str = "durative",
        suboptimality: float = 1.1,
        solver: str = "auto",
        expansion_limit: Optional[int] = DEFAULT_CBS_EXPANSION_LIMIT,
        prioritized_expansions_per_agent: Optional[int] = DEFAULT_PRIORITIZED_EXPANSIONS_PER_AGENT,
        repair_expansions_per_agent: Optional[int] = DEFAULT_REPAIR_EXPANSIONS_PER_AGENT,
        repair_seed: int = 0,
        stepper_expansions_per_agent: Optional[int] = DEFAULT_STEPPER_EXPANSIONS_PER_AGENT,
        lacam_expansions_per_agent: Optional[int] = DEFAULT_LACAM_EXPANSIONS_PER_AGENT,
        time_limit: Optional[float] = None,
        relax_cost: bool = True,
        fallback_suboptimality: Optional[float] = 2.0,
        budget_labels: int = 2_000,
        max_edges: Optional[int] = None,
        cost_guard: Optional[float] = 2.0,
        detour: Optional[float] = None,
        spread_routes: str = "off",
        second_opinion: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
        max_leg: Optional[float] = None,
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
        if not d_max > 0 or not c_max > 0:
            raise ValueError(f"d_max and c_max must be > 0, got {d_max!r}, {c_max!r}")
        if endpoint_edges < 1:
            raise ValueError(f"endpoint_edges must be >= 1, got {endpoint_edges}")
        if proximity_radius is not None and not proximity_radius >= 0:
            raise ValueError(f"proximity_radius must be >= 0 or None, got {proximity_radius!r}")
        self.pairwise = pairwise
        self.d_max = float(d_max)
        self.c_max = float(c_max)
        self.endpoint_edges = int(endpoint_edges)
        self.proximity_radius = proximity_radius
        self.time_model = time_model
        if isinstance(repair_seed, bool) or not isinstance(repair_seed, (int, np.integer)):
            raise ValueError(f"repair_seed must be an integer, got {repair_seed!r}")
        # the solver options, checked by the configuration (the planner's names: solver, repair_seed, spread_routes)
        self._solver_config = SolverConfig(
            name=solver, suboptimality=suboptimality, fallback_suboptimality=fallback_suboptimality,
            expansion_limit=expansion_limit, prioritized_expansions_per_agent=prioritized_expansions_per_agent,
            repair_expansions_per_agent=repair_expansions_per_agent,
            stepper_expansions_per_agent=stepper_expansions_per_agent,
            lacam_expansions_per_agent=lacam_expansions_per_agent, time_limit=time_limit, seed=repair_seed,
            spread=spread_routes)
        for name, factor in (("cost_guard", cost_guard), ("detour", detour)):
            if factor is not None and not factor >= 1.0:
                raise ValueError(f"{name} must be >= 1 or None, got {factor!r}")
        if max_edges is not None and int(max_edges) < 1:
            raise ValueError(f"max_edges must be >= 1 or None, got {max_edges!r}")
        if max_leg is not None and not (max_leg > 0 and (second_opinion is not None or max_leg == math.inf)):
            raise ValueError(f"max_leg must be > 0 and needs a second_opinion to read legs with, got {max_leg!r}")
        config = self._solver_config
        self.solver = config.name
        self.suboptimality = config.suboptimality
        self.fallback_suboptimality = config.fallback_suboptimality
        self.expansion_limit = config.expansion_limit
        self.prioritized_expansions_per_agent = config.prioritized_expansions_per_agent
        self.repair_expansions_per_agent = config.repair_expansions_per_agent
        self.stepper_expansions_per_agent = config.stepper_expansions_per_agent
        self.lacam_expansions_per_agent = config.lacam_expansions_per_agent
        self.repair_seed = config.seed
        self.time_limit = config.time_limit
        self.relax_cost = bool(relax_cost)
        self.budget_labels = int(budget_labels)
        self.max_edges = None if max_edges is None else int(max_edges)
        self.cost_guard = None if cost_guard is None else float(cost_guard)
        self.detour = None if detour is None else float(detour)
        self.spread_routes = config.spread
        self.second_opinion = second_opinion
        self.max_leg = None if max_leg is None else float(max_leg)
        #: the buffer's long legs by (d_max, max_leg), shared by the planners with_options makes
        self._long_legs: Dict[Tuple[float, float], np.ndarray] = {}
        #: the long legs of the last endpoints attached (the buffer's and theirs)
        self._long: Optional[Tuple[Tuple[Any, ...], np.ndarray]] = None
        self._buffer_graph: Optional[WaypointGraph] = None
        #: the last endpoints attached and edges found to pass places to avoid (a replan tries graphs from one place)
        self._attached: Optional[Tuple[Tuple[Any, ...], Tuple[np.ndarray, np.ndarray, np.ndarray]]] = None
        self._passing: Optional[Tuple[Tuple[Any, ...], np.ndarray]] = None

    @property
    def solver_config(self) -> SolverConfig:
        """The solver and its options (``solver``, ``suboptimality``, the budgets, ``time_limit``,
        ``repair_seed``, ``spread_routes``) as one :class:`~agents.search.mapf.registry.SolverConfig`."""
        return self._solver_config

    @property
    def buffer_graph(self) -> WaypointGraph:
        """The buffer nodes' graph pruned at ``d_max`` only (no cost cut-off, no endpoints): the
        graph SoRB searches and the evaluation measures problem difficulty on."""
        if self._buffer_graph is None:
            self._buffer_graph = WaypointGraph.from_matrices(self.D, self.C, d_max=self.d_max,
                                                             observations=self.observations)
        return self._buffer_graph

    @classmethod
    def from_agent(cls, agent, observations: np.ndarray, aggregate: str = "max",
                   bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
                   **kwargs) -> "BufferPlanner":
        """Compute ``D`` and ``C`` with ``agent.pairwise`` (ensemble aggregated by ``aggregate``);
        ``detour`` defaults to :func:`~agents.search.models.default_detour` of ``agent``.

        ``bound(obs_a, obs_b)``: a lower bound of the distance in steps that needs no critic, such
        as the environment's ``min_steps`` (vector observations). Then only the pairs it puts
        below ``d_max`` are read by the critics, here and when starts and goals are attached (see
        :class:`~agents.search.graph.NodePairwise`): on a large map, where most pairs are far
        apart, a graph of thousands of nodes takes seconds instead of minutes. ``D`` and ``C`` are
        then exact only below ``d_max`` (all the planner reads); a pair the bound rules out keeps
        the bound as its distance and :data:`UNREAD_COST` as its cost."""
        obs = np.asarray(observations)
        kwargs.setdefault("detour", default_detour(agent))
        pairwise = NodePairwise(agent, obs, aggregate, bound=bound)  # the nodes are encoded once
        if bound is None:
            D, C = pairwise(obs, obs)
        else:
            D, C = pairwise.within(obs, obs, float(kwargs.get("d_max", DEFAULT_D_MAX)))
            C = np.where(np.isfinite(C), C, UNREAD_COST)
        return cls(obs, D, C, pairwise, **kwargs)

    def options(self) -> Dict[str, Any]:
        """The planner's options (its keyword arguments besides the nodes, matrices and critic)."""
        return dict(
            d_max=self.d_max, c_max=self.c_max, endpoint_edges=self.endpoint_edges,
            proximity_radius=self.proximity_radius, time_model=self.time_model, suboptimality=self.suboptimality,
            solver=self.solver, expansion_limit=self.expansion_limit, repair_seed=self.repair_seed,
            prioritized_expansions_per_agent=self.prioritized_expansions_per_agent,
            repair_expansions_per_agent=self.repair_expansions_per_agent, time_limit=self.time_limit,
            stepper_expansions_per_agent=self.stepper_expansions_per_agent,
            lacam_expansions_per_agent=self.lacam_expansions_per_agent, relax_cost=self.relax_cost,
            fallback_suboptimality=self.fallback_suboptimality, budget_labels=self.budget_labels,
            max_edges=self.max_edges, cost_guard=self.cost_guard, detour=self.detour, spread_routes=self.spread_routes,
            max_leg=self.max_leg)

    def sparsified(self, tau: float, order: Optional[np.ndarray] = None) -> Tuple["BufferPlanner", np.ndarray]:
        """A planner over the nodes kept by two-way consistency merging at ``tau`` steps
        (:func:`~agents.search.sparsify.two_way_consistent`), and the kept node indices."""
        kept = two_way_consistent(self.D, tau, order)
        obs = self.observations[kept]
        pairwise = self.pairwise
        if isinstance(pairwise, NodePairwise):  # it caches the codes of its own nodes
            pairwise = NodePairwise(pairwise.model, obs, pairwise.aggregate)
        ix = np.ix_(kept, kept)
        return BufferPlanner(obs, self.D[ix], self.C[ix], pairwise, second_opinion=self.second_opinion,
                             **self.options()), kept

    def with_options(self, **kwargs) -> "BufferPlanner":
        """A planner over the same nodes and matrices with some options changed (e.g. ``c_max``)."""
        kwargs.setdefault("second_opinion", self.second_opinion)
        out = BufferPlanner(self.observations, self.D, self.C, self.pairwise, **{**self.options(), **kwargs})
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
        :func:`~agents.search.graph.build_problem_graph`; edges that pass a place of ``avoid`` go
        within the proximity radius). Two agents with the same goal are refused (``ValueError``)."""
        starts, goals = check_endpoints(self.observations, starts, goals)
        same = _same_rows(goals)
        if same is not None:
            raise ValueError(f"agents {same[0]} and {same[1]} have the same goal: no plan brings both there (every "
                             "agent needs a place of its own)")
        key = (starts.shape, starts.tobytes(), goals.tobytes())
        if self._attached is None or self._attached[0] != key:
            self._attached = (key, attach_endpoints(self.observations, self.D, self.C, self.pairwise, starts, goals,
                                                    self.d_max))
        passing = None
        if avoid is not None and len(avoid):
            at = np.asarray(avoid, dtype=self.observations.dtype)  # where parked agents stand, say
            k2 = (key, at.shape, at.tobytes())
            if self._passing is None or self._passing[0] != k2:
                D2, _, obs = self._attached[1]
                self._passing = (k2, passing_edges(D2, obs, self.pairwise, at, self.proximity_radius or 0, self.d_max))
            passing = self._passing[1]
        return build_problem_graph(self.observations, self.D, self.C, self.pairwise, starts, goals,
                                   d_max=self.d_max, c_max=self.c_max, endpoint_edges=self.endpoint_edges,
                                   relax_cost=self.relax_cost, exclude=exclude, exclude_edges=exclude_edges,
                                   max_edges=self.max_edges, avoid=avoid, avoid_slack=self.proximity_radius or 0.0,
                                   cost_guard=self.cost_guard, detour=self.detour,
                                   second_opinion=self.second_opinion, detached=detached,
                                   goal_detached=goal_detached, attached=self._attached[1], passing=passing,
                                   max_leg=self.max_leg, long_edges=self._long_edges(key))

    def _long_edges(self, key: Tuple[Any, ...]) -> Optional[np.ndarray]:
        """The edges of the attached problem (``key``: its endpoints) that ``second_opinion`` reads beyond
        ``max_leg``: the buffer's are read once per graph, the endpoints' once per endpoints."""
        if self.max_leg is None or not math.isfinite(self.max_leg):
            return None
        read, n = self.second_opinion, len(self.observations)
        assert read is not None and self._attached is not None  # checked in __init__; attached by the caller
        if (self.d_max, self.max_leg) not in self._long_legs:
            self._long_legs[(self.d_max, self.max_leg)] = long_legs(self.D, self.observations, n, self.d_max, read,
                                                                     self.max_leg)
        if self._long is None or self._long[0] != key:
            D2, _, obs = self._attached[1]
            self._long = (key, long_legs(D2, obs, n, self.d_max, read, self.max_leg,
                                         self._long_legs[(self.d_max, self.max_leg)]))
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
        if self.time_model == "durative":  # an edge takes ceil(D) steps
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
        """Run the solver ``self.solver`` names (:func:`~agents.search.mapf.registry.solve`, ``"auto"``: the
        cascade that picks by the number of agents); ``(result, solver used)``."""
        k = len(s_ids)
        prox = self.problem_proximity(D, k)
        inst = MapfInstance(durations, s_ids, g_ids, time_model=self.time_model, proximity=prox)
        # every budget in the same work on dense graphs; prioritised planning's grows with the graph's size
        res = solve(inst, self._solver_config, scale=self.work_scale(durations), size_scale=self.size_scale())
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
            return MapfResult("infeasible", message="no path from start to goal", time_model=self.time_model,
                              solver="single")
        nodes = route_from_predecessors(pred, s, g)
        path = [(int(v), int(round(dist[v]))) for v in nodes]
        t = int(round(dist[g]))
        return MapfResult("optimal", paths=[path], soc=t, makespan=t, lower_bound=t,
                          message="a single agent: shortest path", time_model=self.time_model, solver="single")

    def problem_proximity(self, D: np.ndarray, k: int) -> Optional[Proximity]:
        """The proximity conflicts of a problem graph with distances ``D`` and ``k`` agents
        (``None`` without a proximity radius): nodes closer than the radius; starts among
        themselves (and goals among themselves) are exempt: agents placed or parked side by side
        by the environment are not a planning conflict, and otherwise such a problem could never
        be solved."""
        if not self.proximity_radius:
            return None
        n = len(self.observations)
        return Proximity(D, self.proximity_radius, exempt=((n, n + k), (n + k, n + 2 * k)))

    @staticmethod
    def _route_cost(C: np.ndarray, nodes: List[int]) -> float:
        a, b = np.array(nodes[:-1], dtype=np.int64), np.array(nodes[1:], dtype=np.int64)
        return float(C[a, b].sum()) if len(a) else 0.0

    def _budget_subgraph(self, graph: WaypointGraph, s_ids, g_ids, budget: float):
        """The graph induced by the nodes of every agent's shortest route within ``budget``."""
        nodes = set()
        for s, g in zip(s_ids, g_ids):
            p = risk_bounded_path(graph, s, g, budget, max_labels=self.budget_labels)
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
