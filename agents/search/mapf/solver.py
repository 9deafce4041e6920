"""The entry point of the MAPF solver: :class:`CBSSolver` (its options) and :func:`solve_cbs`.

The solver checks the instance without searching where it can (unreachable goals, starts or
goals within the proximity radius, an exact two-agent feasibility check of every pair on small
instances), then runs optimal CBS (:mod:`agents.search.mapf.cbs`) or, with
``suboptimality > 1``, ECBS (:mod:`agents.search.mapf.ecbs`) under the time, memory and node
limits, and returns a :class:`~agents.search.mapf.result.MapfResult` (``solver`` ``"cbs"``, the
search's statistics a :class:`~agents.search.mapf.result.CBSStats`). See :mod:`agents.search.mapf`
for the problem and the algorithm.
"""
from __future__ import annotations

import gc
import math
import time as _time
from typing import Any, List, Optional, Sequence, Union

from numpy.typing import ArrayLike

from .cbs import CBSSearch
from .constraints import EMPTY
from .context import SearchContext
from .ecbs import ECBSSearch
from .feasibility import infeasible_component
from .instance import GraphLike, MapfInstance, ProximityLike
from .lowlevel import SearchTimeout
from .paths import spread_mode
from .result import MapfResult
from .symmetry import GridGeometry

#: The high-level heuristics of optimal CBS.
HEURISTICS = ("none", "cg", "dg", "wdg")
#: default ``merge_threshold`` of meta-agent CBS
DEFAULT_MERGE_THRESHOLD = 10
#: default ``merge_space_limit`` of meta-agent CBS (joint configurations of a meta-agent)
DEFAULT_MERGE_SPACE_LIMIT = 2_000
#: default ``joint_check_states``: joint configurations the exhaustive feasibility check may enumerate
DEFAULT_JOINT_CHECK_STATES = 20_000
#: default ``memory_limit_mb``: how much a search may grow the process (MiB)
DEFAULT_MEMORY_LIMIT_MB = 4096.0


def _pair_feasible(inst: MapfInstance, a: int, b: int, work: Optional[List[int]] = None) -> Optional[bool]:
    """Whether agents ``a`` and ``b`` alone can both reach their goals (joint-state search).

    Uses unit-time semantics (vertex, swap, proximity), which every durative plan can be
    serialised into, so ``False`` proves the whole instance infeasible under either model.
    ``work``: a one-element list with the joint moves the search may still examine, decreased as
    it goes; ``None`` is returned when they run out undecided.
    """
    succ = inst.succ
    near = inst.near_mat
    start = (inst.starts[a], inst.starts[b])
    goal = (inst.goals[a], inst.goals[b])
    seen = {start}
    stack = [start]
    popped = 0
    while stack:
        popped += 1
        x, y = stack.pop()
        if work is not None:
            work[0] -= len(succ[x]) * len(succ[y])
            if work[0] < 0:
                return None
        if (x, y) == goal:
            return True
        for x2 in succ[x]:
            for y2 in succ[y]:
                if x2 == y2 or (x2 == y and y2 == x):
                    continue
                if near is not None and near[x2, y2]:
                    continue
                s = (x2, y2)
                if s not in seen:
                    seen.add(s)
                    stack.append(s)
    return False


class CBSSolver:
    """Conflict-Based Search with its options; :meth:`solve` runs it on one instance.

    Args:
        instance: a :class:`MapfInstance`, or the ``graph`` to build one from ``starts``,
            ``goals``, ``time_model`` and ``proximity`` (see :class:`MapfInstance`).
        suboptimality: 1 for optimal CBS; ``w > 1`` for ECBS with cost at most ``w`` x optimal.
        heuristic: high-level heuristic, ``"wdg"`` (default), ``"dg"``, ``"cg"`` or ``"none"``.
        prioritize: choose cardinal, then semi-cardinal conflicts first (via MDDs).
        bypass: adopt a same-cost child path with fewer conflicts instead of branching.
        target_reasoning: resolve target conflicts with length / "never again" constraints.
        symmetry: corridor reasoning (unit time, any graph) and rectangle reasoning (unit
            time, 4-connected grids whose node coordinates are given as ``grid_coords``).
        grid_coords: ``(N, 2)`` integer (row, col) of every node of a 4-connected grid graph.
        vanilla: plain CBS (no prioritisation, bypass, target or symmetry reasoning, heuristic).
        time_limit: wall-clock seconds; the search ends with status ``"timeout"`` (``None``: no wall-clock
            limit, the budgets in work alone end it, so that the outcome never depends on the machine's load).
        memory_limit_mb: how much the process may grow (resident memory, MiB) during the
            search; past it the search ends with status ``"timeout"`` and a message saying so,
            instead of exhausting the machine's memory (long optimal searches keep every open
            constraint-tree node). ``None`` turns the guard off; where the resident size cannot
            be read (no ``/proc`` and no :mod:`resource`) there is no guard.
        node_limit: high-level expansions; the search ends with status ``"timeout"``.
        expansion_limit: low-level expansions over the whole solve (a work budget, checked
            between high-level steps, so the same input stops at the same point on an idle and
            a loaded machine); the search ends with status ``"timeout"``. ``None``: no limit.
        pair_node_limit: high-level expansions of each two-agent search of the WDG heuristic
            (past it the pair's lower bound is used, which keeps the heuristic admissible); an
            agent pair whose searches keep reaching it gets half of it each time, down to 8.
        pair_check_states: an exact two-agent feasibility check of every pair (which can prove
            infeasibility) runs before the search when ``pairs * N**2`` is at most this, and
            once the search has run for a second when it is at most 100 times this.
        joint_check_states: where the joint configurations (placements on distinct nodes) of
            the agents of one connected part of the graph number at most this, an exhaustive
            search over them decides before the search whether those agents can reach their
            goals (:func:`~agents.search.mapf.feasibility.infeasible_component`), so a small
            impossible instance, or an impossible small enclosed part of a larger one, is
            reported ``"infeasible"`` at once instead of after the time limit (0: never).
        merge_threshold: meta-agent CBS (MA-CBS), unit time only: once the splits on conflicts
            between two agents (or meta-agents: summed over their members) number more than
            this in the search, the node being split merges them into one meta-agent instead,
            planned by an optimal coupled search (A* with operator decomposition over the
            members' joint moves, under their constraints, see :mod:`agents.search.mapf.coupled`);
            a coupled search that exhausts its states proves the node (at the root: the
            instance) infeasible. ``None`` turns merging off; ignored under the durative model
            and by ECBS.
        merge_node_limit: expansions of each coupled search; a merge whose search passes it is
            abandoned (not tried again) and the conflict is split as usual; a meta-agent whose
            search passes it in a child is split up again there (its members planned alone).
        merge_max_agents: no meta-agent gets more members than this (the coupled search grows
            exponentially with them); their conflicts are split as usual.
        merge_budget: the coupled searches of a solve may expand 50,000 states plus this many
            times the states the other low-level searches expanded; past that no merge is made
            and a meta-agent that must be replanned is split up again (its members planned
            alone), so that merging costs a bounded share of the search on instances where it
            does not pay. The count is of states, not seconds: the same input gives the same
            search.
        merge_space_limit: merge only into meta-agents whose joint configurations (graph nodes
            to the power of the members) number at most this (``None``: no limit). The default
            keeps merging to tiny, tightly coupled instances (three agents on up to 12 nodes, two
            on up to 44): on the MovingAI benchmark maps a meta-agent's members lose their MDDs
            and WDG edges, and merging was measured to slow the search down several times.
        disjoint_target: split a target conflict (``a1`` parked at its goal ``x`` at ``t``,
            ``a2`` there) disjointly: "``a1`` arrives after ``t``" | "``a1`` arrives at or before
            ``t`` and no agent is at ``x`` from ``t`` on" (instead of "``a2`` alone is never at
            ``x`` from ``t`` on", which overlaps the first branch and needs one split per
            passing agent). Unit time, with ``target_reasoning``.
        pseudo_corridors: with ``symmetry``, split a head-on conflict that is not in a corridor
            of the graph like a corridor of one cell (or of one edge) when both agents' MDDs
            force it: a vertex conflict at ``x`` at ``t`` where every cheapest path of one agent
            goes ``A, x, B`` at ``t - 1, t, t + 1`` and every one of the other ``B, x, A``, or a
            swap conflict both of whose moves are forced. The branches are "the first agent is
            not at ``B`` until ``U1``" | "the second is not at ``A`` until ``U2``", the bounds
            sized from lower bounds on the agents' arrivals so that every solution meets one of
            them (the argument, and the cases left out, are in
            :meth:`agents.search.mapf.symmetry.Corridors.pseudo_split`). Each split resolves
            the whole family of "who waits where" branches of the meeting at once. Unit time;
            off under ``vanilla``. The result's ``stats.pseudo_corridor_splits`` counts them.
        group_bounds: with the WDG heuristic, unit time: bounds beyond pairs. The pair edges of
            the weighted conflict graph cannot see cost that only three or more agents together
            must pay; for a few groups of agents connected in a node's conflict graph (those
            whose pairs the search has split on most often) the optimal joint cost of the group
            alone under the node's constraints is found by the coupled search (memoised by the
            members' constraints, reused from an ancestor's joint plan that still meets them),
            and its excess ``D_G`` over the members' own costs becomes a group constraint
            ``sum_{v in G} x_v >= D_G`` beside the pair constraints ``x_i + x_j >= w_ij``; the
            heuristic is the least ``sum x_v`` meeting all of them (admissible: the extra cost of
            any solution below the node meets every one of them; see
            :meth:`agents.search.mapf.heuristics.ConflictGraphHeuristics._group_constraints`).
            Off under ``vanilla``. ``stats.group_searches``, ``group_reuses``,
            ``group_constraints`` and ``group_raised`` count the coupled searches, the joint
            costs taken from ancestors, the constraints added and the nodes they raised.
        group_max_agents: group size, 3 or more (the candidates of size ``k + 1`` extend those
            of size ``k`` by a conflicting neighbour).
        group_limit: groups evaluated per node at most.
        group_node_limit: expansions of each coupled search of a group (past it the search's
            lower bound is used, which keeps the bound admissible).
        group_budget: the group searches of a solve may expand 50,000 states plus this many
            times the states of the other low-level searches; past that only known joint costs
            (and ancestors' bounds) are used.
        spread: durative model: the low-level searches prefer, among paths of equal cost and
            equally few conflicts, those that enter fewer of the places the other agents' paths
            take at any time (a conflict-avoidance tie-break over places rather than times):
            ``"routes"`` counts the nodes on the other paths, ``"near"`` those and the nodes near
            them, ``"off"`` none. The agents' routes share fewer places, and the plan orders
            fewer of them one after another, with routes no longer than without it. Ignored
            under unit time.
    """

    def __init__(
        self,
        instance: Union[MapfInstance, GraphLike],
        starts: Optional[Sequence[int]] = None,
        goals: Optional[Sequence[int]] = None,
        *,
        time_model: str = "unit",
        proximity: ProximityLike = None,
        suboptimality: float = 1.0,
        heuristic: str = "wdg",
        prioritize: bool = True,
        bypass: bool = True,
        target_reasoning: bool = True,
        symmetry: bool = True,
        grid_coords: Optional[ArrayLike] = None,
        vanilla: bool = False,
        time_limit: Optional[float] = 60.0,
        memory_limit_mb: Optional[float] = DEFAULT_MEMORY_LIMIT_MB,
        node_limit: Optional[int] = None,
        expansion_limit: Optional[int] = None,
        pair_node_limit: int = 64,
        pair_check_states: int = 20_000,
        joint_check_states: int = DEFAULT_JOINT_CHECK_STATES,
        merge_threshold: Optional[int] = DEFAULT_MERGE_THRESHOLD,
        merge_node_limit: int = 100_000,
        merge_max_agents: int = 4,
        merge_budget: float = 0.5,
        merge_space_limit: Optional[int] = DEFAULT_MERGE_SPACE_LIMIT,
        disjoint_target: bool = True,
        pseudo_corridors: bool = True,
        group_bounds: bool = False,
        group_max_agents: int = 3,
        group_limit: int = 4,
        group_node_limit: int = 5_000,
        group_budget: float = 1.0,
        spread: str = "off",
    ) -> None:
        if isinstance(instance, MapfInstance):
            if starts is not None or goals is not None:
                raise ValueError("pass starts/goals only with a graph, not with a MapfInstance")
            self.instance = instance
        else:
            if starts is None or goals is None:
                raise ValueError("starts and goals are required with a graph")
            self.instance = MapfInstance(instance, starts, goals, time_model=time_model, proximity=proximity)
        if heuristic not in HEURISTICS:
            raise ValueError(f"heuristic must be one of {HEURISTICS}, got {heuristic!r}")
        if not (suboptimality >= 1.0):
            raise ValueError(f"suboptimality must be >= 1, got {suboptimality!r}")
        if time_limit is not None and not (time_limit > 0):
            raise ValueError(f"time_limit must be > 0 seconds or None, got {time_limit!r}")
        if memory_limit_mb is not None and not (memory_limit_mb > 0):
            raise ValueError(f"memory_limit_mb must be > 0 (or None for no limit), got {memory_limit_mb!r}")
        if node_limit is not None and node_limit < 0:
            raise ValueError(f"node_limit must be >= 0, got {node_limit!r}")
        if expansion_limit is not None and expansion_limit < 0:
            raise ValueError(f"expansion_limit must be >= 0, got {expansion_limit!r}")
        self.suboptimality = float(suboptimality)
        if merge_threshold is not None and merge_threshold < 0:
            raise ValueError(f"merge_threshold must be >= 0 (or None for no merging), got {merge_threshold!r}")
        if merge_node_limit < 1:
            raise ValueError(f"merge_node_limit must be >= 1, got {merge_node_limit!r}")
        if merge_max_agents < 2:
            raise ValueError(f"merge_max_agents must be >= 2, got {merge_max_agents!r}")
        if merge_space_limit is not None and merge_space_limit < 1:
            raise ValueError(f"merge_space_limit must be >= 1 (or None for no limit), got {merge_space_limit!r}")
        if not (merge_budget >= 0):
            raise ValueError(f"merge_budget must be >= 0, got {merge_budget!r}")
        if group_max_agents < 3:
            raise ValueError(f"group_max_agents must be >= 3, got {group_max_agents!r}")
        if group_limit < 0 or group_node_limit < 1 or not (group_budget >= 0):
            raise ValueError("group_limit must be >= 0, group_node_limit >= 1 and group_budget >= 0")
        if vanilla:
            heuristic, prioritize, bypass, target_reasoning, symmetry = "none", False, False, False, False
            merge_threshold, disjoint_target, pseudo_corridors, group_bounds = None, False, False, False
        self.heuristic = heuristic
        self.prioritize = prioritize
        self.bypass = bypass
        self.target_reasoning = target_reasoning
        self.symmetry = symmetry and prioritize
        self.grid_coords = grid_coords
        if grid_coords is not None:
            GridGeometry(self.instance, grid_coords)  # validate now: a clear error early
        self.time_limit = None if time_limit is None else float(time_limit)
        self.memory_limit_mb = None if memory_limit_mb is None else float(memory_limit_mb)
        self.node_limit = node_limit
        self.expansion_limit = expansion_limit
        self.pair_node_limit = int(pair_node_limit)
        self.pair_check_states = int(pair_check_states)
        if joint_check_states < 0:
            raise ValueError(f"joint_check_states must be >= 0, got {joint_check_states!r}")
        self.joint_check_states = int(joint_check_states)
        self.merge_threshold = None if merge_threshold is None else int(merge_threshold)
        self.merge_node_limit = int(merge_node_limit)
        self.merge_max_agents = int(merge_max_agents)
        self.merge_budget = float(merge_budget)
        self.merge_space_limit = None if merge_space_limit is None else int(merge_space_limit)
        self.disjoint_target = bool(disjoint_target)
        self.pseudo_corridors = bool(pseudo_corridors) and self.symmetry
        self.group_bounds = bool(group_bounds) and heuristic == "wdg"
        self.group_max_agents = int(group_max_agents)
        self.group_limit = int(group_limit)
        self.group_node_limit = int(group_node_limit)
        self.group_budget = float(group_budget)
        self.spread = spread_mode(spread)

    # -------------------------------------------------------------- checks
    def _precheck(self) -> Optional[str]:
        """A reason the instance is infeasible, found without searching, or ``None``."""
        inst = self.instance
        bad = inst.unreachable_agents()
        if bad:
            i = bad[0]
            return f"goal {inst.goals[i]} of agent {i} is unreachable from its start {inst.starts[i]}"
        if inst.near_mat is not None:
            k = inst.n_agents
            for what, nodes in (("start", inst.starts), ("goal", inst.goals)):
                for a in range(k):
                    for b in range(a + 1, k):
                        if inst.near_mat[nodes[a], nodes[b]]:
                            return (f"the {what}s of agents {a} and {b} ({nodes[a]}, {nodes[b]}) are closer "
                                    "than the proximity radius")
        if self._pair_check_size() <= self.pair_check_states:
            reason = self._pair_check()
            if reason is not None:
                return reason
        if self.joint_check_states > 0:
            return infeasible_component(inst, self.joint_check_states)
        return None

    def _pair_check_size(self) -> int:
        k = self.instance.n_agents
        return k * (k - 1) // 2 * self.instance.n_nodes ** 2

    def _pair_check(self, moves: Optional[int] = None) -> Optional[str]:
        """Why some pair of agents cannot both reach their goals, or ``None`` (also when the
        check has examined ``moves`` joint moves undecided: a budget counted in work, so that the
        outcome never depends on the machine's load)."""
        inst = self.instance
        k = inst.n_agents
        work = None if moves is None else [int(moves)]
        for a in range(k):
            for b in range(a + 1, k):
                ok = _pair_feasible(inst, a, b, work)
                if ok is None:  # out of budget: undecided
                    return None
                if not ok:
                    return (f"agents {a} and {b} cannot both reach their goals: every plan of the two makes them "
                            "collide with each other (each may reach its goal alone; the other agents aside)")
        return None

    # -------------------------------------------------------------- solve
    def solve(self) -> MapfResult:
        """Run the search and return a :class:`~agents.search.mapf.result.MapfResult` (never raises on a
        hard instance); ``work`` counts the low-level expansions."""
        # the search allocates many small long-lived objects; with the default thresholds the
        # cyclic garbage collector keeps rescanning them (about a fifth of the run time), so it
        # runs less often during the search (the thresholds are restored afterwards)
        old = gc.get_threshold()
        gc.set_threshold(max(old[0], 100_000), max(old[1], 50), max(old[2], 100))
        try:
            return self._solve()
        finally:
            gc.set_threshold(*old)

    def _solve(self) -> MapfResult:
        t0 = _time.perf_counter()
        inst = self.instance
        ctx = SearchContext(inst, math.inf if self.time_limit is None else t0 + self.time_limit, self)
        stats = ctx.stats

        def finish(res: MapfResult) -> MapfResult:
            stats.ll_calls = ctx.counter.calls
            res.stats = stats
            res.work = ctx.counter.expanded
            res.runtime_s = _time.perf_counter() - t0
            res.solver = "cbs"
            res.time_model = inst.time_model
            return res

        if inst.n_agents == 0:
            return finish(MapfResult("optimal", [], 0, 0, 0, message="no agents"))
        reason = self._precheck()
        if reason is not None:
            return finish(MapfResult("infeasible", message=reason))
        w = self.suboptimality
        search: CBSSearch
        if w > 1.0:
            ecbs = ECBSSearch(ctx, w, self.target_reasoning, self.node_limit)
            search, run = ecbs, ecbs.run_focal
        else:
            search = CBSSearch(ctx, list(range(inst.n_agents)), [EMPTY] * inst.n_agents,
                               heuristic=self.heuristic, prioritize=self.prioritize, bypass=self.bypass,
                               target_reasoning=self.target_reasoning, node_limit=self.node_limit,
                               symmetry=self.symmetry, merge_threshold=self.merge_threshold,
                               merge_node_limit=self.merge_node_limit, merge_max_agents=self.merge_max_agents,
                               merge_budget=self.merge_budget, merge_space_limit=self.merge_space_limit,
                               disjoint_target=self.disjoint_target, pseudo_corridors=self.pseudo_corridors,
                               group_bounds=self.group_bounds, group_max_agents=self.group_max_agents,
                               group_limit=self.group_limit, group_node_limit=self.group_node_limit,
                               group_budget=self.group_budget)
            run = search.run
        try:
            status, node = run()
        except SearchTimeout:
            lb = search.lower_bound or None
            if ctx.stop_reason == "work":
                msg = f"expansion limit of {self.expansion_limit} low-level expansions reached"
            elif ctx.stop_reason == "memory":
                msg = (f"memory limit reached: the search grew the process by more than "
                       f"{self.memory_limit_mb:g} MiB (memory_limit_mb)")
            else:
                msg = f"time limit of {self.time_limit} s reached"
            return finish(MapfResult("timeout", lower_bound=lb, message=msg))
        if status == "infeasible":
            msg = ctx.infeasible_reason or "the constraint tree was exhausted: no solution exists"
            return finish(MapfResult("infeasible", message=msg))
        if status == "limit":
            return finish(MapfResult("timeout", lower_bound=search.lower_bound or None,
                                     message=f"node limit of {self.node_limit} expansions reached"))
        assert node is not None  # "solved" comes with its node
        paths = [list(p.events) for p in node.paths]
        soc = sum(p.cost for p in node.paths)
        makespan = max(p.cost for p in node.paths)
        if w > 1.0:
            lb = min(search.lower_bound, soc)
            st = "optimal" if lb >= soc else "suboptimal"
            msg = f"cost within {w:g} x optimal" if st == "suboptimal" else "cost equals the proven lower bound"
        else:
            lb, st, msg = soc, "optimal", "optimal sum of costs"
        return finish(MapfResult(st, paths, soc, makespan, lb, message=msg))


def solve_cbs(
    graph: GraphLike,
    starts: Sequence[int],
    goals: Sequence[int],
    *,
    time_model: str = "unit",
    proximity: ProximityLike = None,
    suboptimality: float = 1.0,
    time_limit: Optional[float] = 60.0,
    node_limit: Optional[int] = None,
    vanilla: bool = False,
    **options: Any,
) -> MapfResult:
    """Solve a multi-agent path finding instance with CBS (or ECBS if ``suboptimality > 1``).

    ``graph`` holds edge durations (scipy sparse / dense matrix or adjacency list); see
    :class:`CBSSolver` for the options. Returns a :class:`~agents.search.mapf.result.MapfResult`; raises
    ``ValueError`` only for malformed input (bad node ids, duplicate starts or goals, bad durations).
    """
    return CBSSolver(graph, starts, goals, time_model=time_model, proximity=proximity,
                     suboptimality=suboptimality, time_limit=time_limit, node_limit=node_limit,
                     vanilla=vanilla, **options).solve()
