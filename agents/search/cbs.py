"""Conflict-Based Search (CBS) for multi-agent path finding on any directed graph.

This is the multi-agent planner of "Safe Multi-Agent Navigation guided by Goal-Conditioned
Safe Reinforcement Learning": waypoints on the replay-buffer graph are planned for several
agents at once so that their timed paths never collide. The solver is general and depends on
numpy/scipy only.

Problem
    A directed graph with integer edge durations (a scipy sparse matrix, a dense matrix or an
    adjacency list), one start and one goal node per agent. Waiting in place is always allowed
    and takes one step. An agent stays at its goal forever after its final arrival. The cost of
    a solution is the sum over agents of their final arrival times (sum of costs, SOC).

Time models
    ``"unit"``: every move takes one step (the MAPF benchmark semantics and the paper's
    unit-time mode). ``"durative"``: a move takes its integer duration, so plan time is
    environment time. In the durative model an agent traversing ``u -> v`` during
    ``[t, t + d)`` is taken to occupy *both* ``u`` and ``v`` (and their neighbourhoods under
    proximity) for the whole traversal; this is conservative: it also forbids entering a node
    during the step in which another agent leaves it.

Conflicts
    vertex, edge (swap; unit time), target (an agent runs into another one parked at its goal)
    and proximity (two agents at distinct nodes closer than a radius under a user-given
    node-distance function, e.g. a distance critic's predictions).

Algorithm
    Optimal CBS with prioritised conflicts (cardinal / semi-cardinal, classified with MDDs),
    bypass, target reasoning and an admissible high-level heuristic (``"cg"``: cardinal
    conflict graph, ``"dg"``: dependency graph, ``"wdg"``: weighted dependency graph, solved as
    an edge-weighted minimum vertex cover). With a heuristic, the conflict to split is chosen
    f-aware: first the splits whose children get larger lower bounds (the raised agent's edges
    of the weighted conflict graph lowered by its cost increase, the cover recomputed), and a
    child that must raise its agent's cost is planned only when it is popped. Results that
    depend only on constraints (MDDs, pair sub-problems) are cached by constraint content.
    ``suboptimality=w > 1`` switches to ECBS (focal search at both levels; the returned cost is
    at most ``w`` times the optimum). ``vanilla=True`` turns prioritisation, bypass, target and
    symmetry reasoning and the heuristic off.

Public API
    :func:`solve_cbs`, :class:`CBSSolver`, :class:`CBSResult`, :class:`CBSStats`,
    :class:`CTNode`, :class:`Proximity`, :class:`MapfInstance`, :func:`integer_durations`,
    and :func:`agents.search.validate.validate` to check any solution independently.
"""
from __future__ import annotations

import gc
import heapq
import itertools
import os
import sys
import time as _time
from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

from .cbs_lowlevel import (
    AgentPath,
    Counter,
    MDD,
    Reservation,
    SearchTimeout,
    build_mdd,
    earliest_arrival,
    focal_search,
    mdds_dependent,
    pair_conflicts,
    prune_mdd,
    satisfies,
    space_time_astar,
)
from .constraints import (
    CARDINAL,
    EDGE,
    TARGET,
    VERTEX,
    EMPTY,
    FOREVER,
    NON_CARDINAL,
    SEMI_CARDINAL,
    Conflict,
    ConstraintSet,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
from .mapf_instance import MapfInstance, Proximity, integer_durations
from .symmetry import Corridors, GridGeometry

__all__ = [
    "CBSResult",
    "CBSSolver",
    "CBSStats",
    "CTNode",
    "MapfInstance",
    "Proximity",
    "STATUSES",
    "integer_durations",
    "solve_cbs",
]

#: Possible values of :attr:`CBSResult.status`.
STATUSES = ("optimal", "suboptimal", "timeout", "infeasible")
HEURISTICS = ("none", "cg", "dg", "wdg")
_INF = 1 << 50
#: how many constraint-set ancestors are searched for an MDD or pair result to reuse
_ANCESTORS = 8
#: the memory guard reads the process's resident size once every this many checks
_MEMORY_CHECK_EVERY = 256
#: default ``memory_limit_mb``: how much a search may grow the process (MiB)
DEFAULT_MEMORY_LIMIT_MB = 4096.0


def _rss_bytes() -> Optional[int]:
    """The resident memory of this process in bytes, or ``None`` where it cannot be read.

    Linux: the current resident size (``/proc/self/statm``). Elsewhere with :mod:`resource`:
    the peak resident size, which only grows (still a valid guard). Otherwise ``None``.
    """
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024


# ---------------------------------------------------------------------------------- results
@dataclass
class CBSStats:
    """Search statistics of one solve."""

    hl_expanded: int = 0
    hl_generated: int = 0
    ll_expanded: int = 0
    ll_calls: int = 0
    runtime_s: float = 0.0
    mdds: int = 0
    pair_searches: int = 0
    pair_reuses: int = 0
    bypasses: int = 0


@dataclass
class CBSResult:
    """The outcome of a CBS solve.

    Attributes:
        status: ``"optimal"``, ``"suboptimal"`` (ECBS; cost within ``suboptimality`` x optimum),
            ``"timeout"`` (time, memory or node limit reached first) or ``"infeasible"`` (proved).
        paths: per agent, the timed path ``[(node, time), ...]``: the agent is at ``node`` at
            ``time``; one entry per time step under unit time; arrivals and each waiting step
            under the durative model (between two entries ``(u, t), (v, t + d)`` with ``u != v``
            the agent traverses the edge). The last entry is the final arrival at the goal, where
            the agent then stays. ``None`` unless solved.
        soc: sum over agents of the final arrival times.
        makespan: the latest final arrival time.
        lower_bound: a proven lower bound on the optimal sum of costs (``None`` if unknown).
        stats: search statistics.
        message: why the search ended the way it did, in words.
        time_model: ``"unit"`` or ``"durative"``.
    """

    status: str
    paths: Optional[List[List[Tuple[int, int]]]] = None
    soc: Optional[int] = None
    makespan: Optional[int] = None
    lower_bound: Optional[int] = None
    stats: CBSStats = field(default_factory=CBSStats)
    message: str = ""
    time_model: str = "unit"

    @property
    def solved(self) -> bool:
        """Whether paths were found."""
        return self.paths is not None

    def node_sequences(self, pad: bool = False) -> List[List[int]]:
        """Per agent, the node at every time step ``0..arrival`` (``0..makespan`` if ``pad``).

        Under the durative model a step spent traversing an edge reports the node the agent
        left (its most recent node).
        """
        if self.paths is None:
            raise ValueError(f"no paths: the search ended with status {self.status!r}")
        out = []
        horizon = self.makespan or 0
        for events in self.paths:
            seq: List[int] = []
            for (u, t0), (_, t1) in zip(events, events[1:]):
                seq.extend([u] * (t1 - t0))
            seq.append(events[-1][0])
            if pad:
                seq.extend([seq[-1]] * (horizon + 1 - len(seq)))
            out.append(seq)
        return out

    def departures(self, agent: int) -> List[Tuple[int, int]]:
        """Waypoints of one agent as ``(node, departure time)``; the goal's time is its arrival.

        Consecutive waits collapse into one waypoint, which is what a waypoint-following
        controller needs ("do not leave node ``k`` before time ``t_k``").
        """
        if self.paths is None:
            raise ValueError(f"no paths: the search ended with status {self.status!r}")
        events = self.paths[agent]
        out: List[Tuple[int, int]] = []
        for i, (v, t) in enumerate(events):
            if i + 1 < len(events) and events[i + 1][0] == v:
                continue  # still waiting here
            out.append((v, t))
        return out

    def to_dict(self) -> dict:
        """A JSON-friendly summary (paths included)."""
        d = {
            "status": self.status,
            "soc": self.soc,
            "makespan": self.makespan,
            "lower_bound": self.lower_bound,
            "message": self.message,
            "time_model": self.time_model,
        }
        d.update(asdict(self.stats))
        d["paths"] = None if self.paths is None else [[list(e) for e in p] for p in self.paths]
        return d


# ---------------------------------------------------------------------------------- CT nodes
class CTNode:
    """A node of the constraint tree.

    Ordered by ``(f, n_conflicts, id)``: the lowest cost bound first, then the fewest conflicts,
    then creation order, so the search is deterministic.
    """

    __slots__ = ("g", "h", "f", "id", "depth", "paths", "cons", "conflicts", "n_conflicts", "h_done",
                 "lb", "closed", "pending", "hedges", "hmemo")

    def __init__(self, g: int, paths: List[AgentPath], cons: List[ConstraintSet],
                 conflicts: Dict[Tuple[int, int], List[Conflict]], node_id: int, depth: int = 0, h: int = 0):
        self.g = g
        self.h = h
        self.f = g + h
        self.id = node_id
        self.depth = depth
        self.paths = paths
        self.cons = cons
        self.conflicts = conflicts
        self.n_conflicts = sum(len(v) for v in conflicts.values())
        self.h_done = False
        self.lb = g
        self.closed = False
        #: ``(parent, local agent, constraint set)`` while the node is not generated yet: its
        #: path is planned when it is first popped (``g`` and ``f`` are lower bounds until then)
        self.pending = None
        #: the weighted conflict graph ``{(i, j): weight}`` the heuristic was computed from
        self.hedges: Optional[Dict[Tuple[int, int], int]] = None
        #: child bounds computed from ``hedges`` (see ``_CBS._child_bound``)
        self.hmemo: Optional[dict] = None

    def set_conflicts(self, conflicts: Dict[Tuple[int, int], List[Conflict]]) -> None:
        self.conflicts = conflicts
        self.n_conflicts = sum(len(v) for v in conflicts.values())

    def __lt__(self, other: "CTNode") -> bool:
        if self.f != other.f:
            return self.f < other.f
        if self.n_conflicts != other.n_conflicts:
            return self.n_conflicts < other.n_conflicts
        return self.id < other.id

    def __repr__(self) -> str:
        return f"CTNode(id={self.id}, g={self.g}, h={self.h}, f={self.f}, conflicts={self.n_conflicts})"


class _Context:
    """What every search of one solve shares: the instance, limits, caches and counters."""

    def __init__(self, inst: MapfInstance, deadline: float, options: "CBSSolver"):
        self.inst = inst
        self.deadline = deadline
        self.opt = options
        #: resident-memory ceiling in bytes (the process's size at the start plus the limit)
        self.memory_cap: Optional[int] = None
        if options.memory_limit_mb is not None:
            base = _rss_bytes()
            if base is not None:
                self.memory_cap = base + int(options.memory_limit_mb * (1 << 20))
        self._checks = 0
        #: ``"time"`` or ``"memory"``: which limit ended the search
        self.stop_reason = "time"
        self.counter = Counter()
        self.mdds: Dict[Tuple[int, int], MDD] = {}
        self.pairs: Dict[Tuple[int, int, int, int], int] = {}
        #: pair key -> (optimal cost, the two paths) of solved pair sub-problems (unit time)
        self.pair_solutions: Dict[Tuple[int, int, int, int], Tuple[int, AgentPath, AgentPath]] = {}
        #: per agent pair, how many of its pair searches stopped at their node limit
        self.pair_limit_hits: Dict[Tuple[int, int], int] = {}
        self.dependent: Dict[Tuple[int, int, int, int], bool] = {}
        self.arrivals: Dict[Tuple[int, int, int, Optional[int]], int] = {}
        self.compiled: Dict[Tuple[int, int], object] = {}
        self.stats = CBSStats()
        self.ids = itertools.count()
        self._corridors = None
        self.geometry = None
        size = options._pair_check_size()
        #: when to run the deferred pair feasibility check (None: never)
        self.pair_check_at: Optional[float] = (
            _time.perf_counter() + 1.0
            if options.pair_check_states < size <= 100 * options.pair_check_states else None)
        self.infeasible_reason: Optional[str] = None
        if options.symmetry and inst.unit and options.grid_coords is not None:
            self.geometry = GridGeometry(inst, options.grid_coords)

    def corridors(self) -> Optional[Corridors]:
        """The corridor index (built on first use; unit time only)."""
        if self._corridors is None and self.opt.symmetry and self.inst.unit:
            self._corridors = Corridors(self.inst)
        return self._corridors

    def compile(self, gid: int, cons: ConstraintSet):
        key = (gid, cons.content)
        cc = self.compiled.get(key)
        if cc is None:
            cc = compile_constraints(cons, self.inst.n_nodes, self.inst.goals[gid])
            if len(self.compiled) > 200_000:
                self.compiled.clear()
            self.compiled[key] = cc
        return cc

    def check_time(self) -> None:
        """Raise :class:`SearchTimeout` past the deadline or (checked now and then) the memory cap."""
        if _time.perf_counter() > self.deadline:
            raise SearchTimeout
        if self.memory_cap is not None:
            self._checks += 1
            if self._checks % _MEMORY_CHECK_EVERY == 1:
                rss = _rss_bytes()
                if rss is not None and rss > self.memory_cap:
                    self.stop_reason = "memory"
                    raise SearchTimeout


# ---------------------------------------------------------------------------------- vertex cover
_mvc_cache: Dict[Tuple, int] = {}


def _min_vertex_cover(edges: Dict[Tuple[int, int], int]) -> int:
    """Edge-weighted minimum vertex cover: min sum x_v with x_i + x_j >= w_ij, x >= 0 integers.

    Exact per connected component up to 12 vertices (branch and bound, cached by component);
    larger components use a matching lower bound (still admissible).
    """
    if not edges:
        return 0
    return sum(val for _, _, val in _mvc_components(edges))


def _mvc_components(edges: Dict[Tuple[int, int], int]) -> List[Tuple[List[int], Dict[Tuple[int, int], int], int]]:
    """Per connected component of the positive-weight edges: ``(vertices, edges, cover value)``."""
    adj: Dict[int, Dict[int, int]] = {}
    for (i, j), w in edges.items():
        if w <= 0:
            continue
        adj.setdefault(i, {})[j] = max(w, adj.get(i, {}).get(j, 0))
        adj.setdefault(j, {})[i] = max(w, adj.get(j, {}).get(i, 0))
    out = []
    seen = set()
    for root in sorted(adj):
        if root in seen:
            continue
        comp = []
        stack = [root]
        seen.add(root)
        while stack:
            v = stack.pop()
            comp.append(v)
            for u in adj[v]:
                if u not in seen:
                    seen.add(u)
                    stack.append(u)
        comp.sort()
        cedges = tuple(sorted((i, j, w) for i in comp for j, w in adj[i].items() if i < j))
        cdict = {(i, j): w for i, j, w in cedges}
        if len(cedges) == 1:
            out.append((comp, cdict, cedges[0][2]))
            continue
        key = _canonical(comp, cedges)
        val = _mvc_cache.get(key)
        if val is None:
            val = _mvc_exact(comp, adj) if len(comp) <= 12 else _matching_bound(cedges)
            if len(_mvc_cache) > 100_000:
                _mvc_cache.clear()
            _mvc_cache[key] = val
        out.append((comp, cdict, val))
    return out


def _canonical(comp: List[int], cedges: Tuple[Tuple[int, int, int], ...]) -> Tuple:
    index = {v: k for k, v in enumerate(comp)}
    return tuple(sorted((index[i], index[j], w) for i, j, w in cedges))


def _matching_bound(cedges: Tuple[Tuple[int, int, int], ...]) -> int:
    used = set()
    total = 0
    for i, j, w in sorted(cedges, key=lambda e: (-e[2], e[0], e[1])):
        if i not in used and j not in used:
            used.add(i)
            used.add(j)
            total += w
    return total


def _mvc_exact(comp: List[int], adj: Dict[int, Dict[int, int]]) -> int:
    order = sorted(comp, key=lambda v: (-len(adj[v]), v))
    pos = {v: k for k, v in enumerate(order)}
    n = len(order)
    nbrs = [[(pos[u], w) for u, w in adj[v].items()] for v in order]
    maxw = [max(w for _, w in nb) for nb in nbrs]
    best = [sum(maxw)]
    x = [0] * n

    def lower(k: int) -> int:
        # every unassigned vertex needs at least the largest residual towards assigned ones
        s = 0
        for v in range(k, n):
            need = 0
            for u, w in nbrs[v]:
                if u < k:
                    r = w - x[u]
                    if r > need:
                        need = r
            s += need
        return s

    def rec(k: int, cost: int) -> None:
        if cost + lower(k) >= best[0]:
            return
        if k == n:
            best[0] = cost
            return
        lo = 0
        for u, w in nbrs[k]:
            if u < k and w - x[u] > lo:
                lo = w - x[u]
        for val in range(lo, maxw[k] + 1):
            x[k] = val
            rec(k + 1, cost + val)
        x[k] = 0

    rec(0, 0)
    return best[0]


# ---------------------------------------------------------------------------------- optimal CBS
class _CBS:
    """One CBS search (the main one, or a two-agent sub-problem of the WDG heuristic)."""

    def __init__(self, ctx: _Context, agents: List[int], init_cons: List[ConstraintSet], *,
                 heuristic: str, prioritize: bool, bypass: bool, target_reasoning: bool,
                 node_limit: Optional[int], sub: bool = False,
                 init_paths: Optional[List[AgentPath]] = None, symmetry: bool = True):
        self.ctx = ctx
        self.inst = ctx.inst
        self.agents = agents
        self.local = {g: i for i, g in enumerate(agents)}
        self.init_cons = init_cons
        self.heuristic = heuristic
        self.prioritize = prioritize
        self.use_bypass = bypass
        self.tr = target_reasoning
        self.node_limit = node_limit
        self.sub = sub
        self.init_paths = init_paths
        self.symmetry = symmetry
        self.lower_bound = 0
        self.expanded = 0

    # -------------------------------------------------------------- low level
    def _plan(self, i: int, cons: ConstraintSet, paths: List[Optional[AgentPath]]) -> Optional[AgentPath]:
        ctx = self.ctx
        gid = self.agents[i]
        cc = ctx.compile(gid, cons)
        res = Reservation(paths, i, self.inst) if len(paths) > 1 else None
        events = space_time_astar(self.inst, gid, cc, res, ctx.deadline, ctx.counter)
        if events is None:
            return None
        return AgentPath(events, self.inst)

    def _detect(self, i: int, path: AgentPath, paths: List[AgentPath],
                conflicts: Dict[Tuple[int, int], List[Conflict]], upto: Optional[int] = None) -> None:
        gi = self.agents[i]
        inst = self.inst
        for j, pj in enumerate(paths):
            if j == i or pj is None or (upto is not None and j >= upto):
                continue
            found = pair_conflicts(gi, path, self.agents[j], pj, inst)
            if found:
                conflicts[(i, j) if i < j else (j, i)] = found

    # -------------------------------------------------------------- MDDs and classification
    def _mdd(self, node: CTNode, i: int) -> MDD:
        gid = self.agents[i]
        cons = node.cons[i]
        key = (gid, cons.content)
        ctx = self.ctx
        m = ctx.mdds.get(key)
        if m is None:
            ctx.check_time()
            cc = ctx.compile(gid, cons)
            cost = node.paths[i].cost
            if self.inst.unit:
                # an ancestor constraint set's MDD of the same cost, pruned, is this one
                anc = cons.parent
                for _ in range(_ANCESTORS):
                    if anc is None:
                        break
                    old = ctx.mdds.get((gid, anc.content))
                    if old is not None and old.cost == cost:
                        m = prune_mdd(old, cc)
                        break
                    anc = anc.parent
            if m is None:
                m = build_mdd(self.inst, gid, cc, cost)
            ctx.stats.mdds += 1
            if len(ctx.mdds) > 50_000:
                ctx.mdds.clear()
            ctx.mdds[key] = m
        return m

    def _raises_cost(self, node: CTNode, i: int, constraints) -> bool:
        """Whether every optimal path of local agent ``i`` violates ``constraints``."""
        path = node.paths[i]
        cost = path.cost
        for c in constraints:
            if isinstance(c, LengthConstraint):
                if c.time >= cost:
                    return True
                continue
            if isinstance(c, VertexConstraint):
                if c.time >= cost:
                    if c.node == path.goal:
                        return True
                    continue
                m = self._mdd(node, i)
                if c.node in m.must[c.time]:
                    return True
                continue
            if isinstance(c, EdgeConstraint):
                if c.time + 1 > cost:
                    continue
                m = self._mdd(node, i)
                if c.u in m.must[c.time] and c.v in m.must[c.time + 1]:
                    return True
                continue
            if isinstance(c, RangeConstraint):
                m = self._mdd(node, i)
                if c.end >= FOREVER:
                    if not m.avoidable(c.node, c.start, self.inst.unit):
                        return True
                continue
        return False

    def _classify(self, node: CTNode, c: Conflict) -> int:
        if c.cls is not None:
            return c.cls
        (i1, cons1), (i2, cons2) = c.branches(self.tr)
        l1, l2 = self.local[i1], self.local[i2]
        c.card1 = self._raises_cost(node, l1, cons1)
        c.card2 = self._raises_cost(node, l2, cons2)
        c.cls = CARDINAL if (c.card1 and c.card2) else (SEMI_CARDINAL if (c.card1 or c.card2) else NON_CARDINAL)
        return c.cls

    def _symmetric_split(self, node: CTNode, c: Conflict):
        """A corridor or rectangle split for ``c``: ``(class, branches, forced)``, or ``None``."""
        ctx = self.ctx
        if c.kind not in (VERTEX, EDGE):
            return None
        l1, l2 = self.local[c.a1], self.local[c.a2]
        p1, p2 = node.paths[l1], node.paths[l2]
        corridors = ctx.corridors()
        if corridors is not None:
            def earliest(gid: int, target: int, cid: Optional[int]) -> int:
                cons = node.cons[self.local[gid]]
                key = (gid, cons.content, target, cid)
                val = ctx.arrivals.get(key)
                if val is None:
                    blocked = corridors.inner_sets[cid] if cid is not None else frozenset()
                    val = earliest_arrival(self.inst, gid, ctx.compile(gid, cons), target, blocked,
                                           ctx.deadline, ctx.counter)
                    if len(ctx.arrivals) > 200_000:
                        ctx.arrivals.clear()
                    ctx.arrivals[key] = val
                return val

            br = corridors.split(c, c.a1, p1, c.a2, p2, earliest)
            if br is not None:
                cards = []
                for gid, cons in br:
                    i = self.local[gid]
                    rc = cons[0]
                    m = self._mdd(node, i)
                    cards.append(not m.avoidable(rc.node, rc.start, True, rc.end))
                cls = CARDINAL if all(cards) else (SEMI_CARDINAL if any(cards) else NON_CARDINAL)
                return cls, br, tuple(cards)
        geom = ctx.geometry
        if geom is not None and c.kind == VERTEX:
            br = geom.split(c, c.a1, self._mdd(node, l1), c.a2, self._mdd(node, l2))
            if br is not None:
                return CARDINAL, br, (True, True)
        return None

    def _choose(self, node: CTNode):
        """The conflict to split on and its branches ``[(agent, constraints), ...]``."""
        return self._choose_forced(node)[0]

    def _choose_forced(self, node: CTNode):
        """:meth:`_choose`, and per branch whether it is known to raise its agent's cost."""
        allc = [c for lst in node.conflicts.values() for c in lst]
        allc.sort(key=lambda c: (c.time, c.a1, c.a2))
        if not self.prioritize:
            return allc[0].branches(self.tr), (False, False)
        for c in allc:
            self._classify(node, c)
        tr = self.tr
        allc.sort(key=lambda c: (c.cls, 0 if (c.kind == TARGET and tr) else 1, c.time, c.a1, c.a2))
        best_key = None
        best = None
        symmetric = self.symmetry and self.inst.unit
        # f-aware choice: with the weighted conflict graph known, prefer the splits whose
        # children get larger lower bounds (see _child_bound), then cardinal ones, etc.
        faware = node.hedges is not None
        for c in allc:
            # rank 0: target, corridor or rectangle reasoning; rank 1: a plain split
            key = (c.cls, 0 if (c.kind == TARGET and self.tr) else 1, c.time)
            branches = None
            forced = (c.card1, c.card2)
            if symmetric:
                if not c.sym_done:
                    c.sym = self._symmetric_split(node, c)
                    c.sym_done = True
                sym = c.sym
                if sym is not None:
                    key = (min(sym[0], c.cls), 0, c.time)
                    branches = sym[1]
                    forced = sym[2]
            if faware:
                # (how many children get a larger bound, the smaller and the larger child bound)
                brs = branches if branches is not None else c.branches(self.tr)
                fs = [self._child_bound(node, self.local[gid], cons, True)[1] if fc else node.f
                      for (gid, cons), fc in zip(brs, forced)]
                raised = sum(1 for f in fs if f > node.f)
                key = (-raised, -min(fs), -max(fs)) + key
            if best_key is None or key < best_key:
                best_key = key
                best = (branches if branches is not None else c, forced)
                if not faware and key[:2] == (CARDINAL, 0):
                    break
            if not symmetric and not faware and best_key is not None:
                break  # sorted by class and time already
        split, forced = best
        if isinstance(split, Conflict):
            return split.branches(self.tr), forced
        return split, forced

    # -------------------------------------------------------------- heuristic
    def _pair_cardinal(self, node: CTNode, lst: List[Conflict]) -> bool:
        for c in lst:
            if self._classify(node, c) == CARDINAL:
                return True
        return False

    def _dependent(self, node: CTNode, i: int, j: int) -> bool:
        """Whether no two optimal paths of i and j avoid each other (memoised MDD merge)."""
        key = (self.agents[i], self.agents[j], node.cons[i].content, node.cons[j].content)
        dep = self.ctx.dependent.get(key)
        if dep is None:
            dep = mdds_dependent(self._mdd(node, i), self._mdd(node, j), self.inst.near_mat)
            if len(self.ctx.dependent) > 500_000:
                self.ctx.dependent.clear()
            self.ctx.dependent[key] = dep
        return dep

    def _pair_known(self, node: CTNode, i: int, j: int) -> Optional[int]:
        """The optimal cost of the pair (i, j) alone under the node's constraints, if known
        without a search: memoised, or (unit time) the optimum of the pair under an ancestor
        constraint set of one of the two agents whose solution meets the constraints added since
        (more constraints cannot make the pair cheaper, and that solution is still allowed)."""
        ctx = self.ctx
        gi, gj = self.agents[i], self.agents[j]
        ci, cj = node.cons[i], node.cons[j]
        val = ctx.pairs.get((gi, gj, ci.content, cj.content))
        if val is not None or not self.inst.unit:
            return val
        for side in (0, 1):
            cur = ci if side == 0 else cj
            walked = []
            for _ in range(_ANCESTORS):
                if cur.parent is None:
                    break
                walked.append(cur.constraint)
                cur = cur.parent
                key = (gi, gj, cur.content, cj.content) if side == 0 else (gi, gj, ci.content, cur.content)
                sol = ctx.pair_solutions.get(key)
                if sol is not None:
                    total, pi, pj = sol
                    p = pi if side == 0 else pj
                    if all(satisfies(p, c) for c in walked):
                        ctx.pairs[(gi, gj, ci.content, cj.content)] = total
                        ctx.stats.pair_reuses += 1
                        return total
        return None

    def _pair_weight(self, node: CTNode, i: int, j: int) -> int:
        """Extra cost the pair (i, j) needs beyond their individual optima (memoised)."""
        ctx = self.ctx
        gi, gj = self.agents[i], self.agents[j]
        ci, cj = node.cons[i], node.cons[j]
        key = (gi, gj, ci.content, cj.content)
        val = self._pair_known(node, i, j)
        if val is None:
            ctx.stats.pair_searches += 1
            # a pair whose searches keep running into the limit gets smaller limits (its weight
            # is then a lower bound, as with any search that stops at the limit)
            hits = ctx.pair_limit_hits.get((gi, gj), 0)
            limit = max(ctx.opt.pair_node_limit >> hits, min(8, ctx.opt.pair_node_limit))
            sub = _CBS(ctx, [gi, gj], [ci, cj], heuristic="cg", prioritize=True, bypass=True,
                       target_reasoning=self.tr, node_limit=limit, sub=True,
                       init_paths=[node.paths[i], node.paths[j]], symmetry=self.symmetry)
            status, best = sub.run()
            if status == "limit":
                ctx.pair_limit_hits[(gi, gj)] = hits + 1
            if status == "solved":
                total = best.g
                if self.inst.unit:
                    if len(ctx.pair_solutions) > 200_000:
                        ctx.pair_solutions.clear()
                    ctx.pair_solutions[key] = (total, best.paths[0], best.paths[1])
            elif status == "infeasible":
                total = _INF
            else:
                total = sub.lower_bound
            if len(ctx.pairs) > 200_000:
                ctx.pairs.clear()
            ctx.pairs[key] = total
            val = total
        if val >= _INF:
            return _INF
        return max(0, val - node.paths[i].cost - node.paths[j].cost)

    def _compute_h(self, node: CTNode) -> int:
        if self.heuristic == "none" or not node.conflicts:
            return 0
        edges: Dict[Tuple[int, int], int] = {}
        unit = self.inst.unit
        for (i, j), lst in node.conflicts.items():
            card = self._pair_cardinal(node, lst)
            if self.heuristic == "cg":
                if card:
                    edges[(i, j)] = 1
                continue
            if self.heuristic == "wdg" and self._pair_known(node, i, j) is not None:
                w = self._pair_weight(node, i, j)  # no search: known already
            else:
                dep = card
                if not dep and unit:
                    dep = self._dependent(node, i, j)
                if self.heuristic == "dg":
                    if dep:
                        edges[(i, j)] = 1
                    continue
                if not dep and unit:
                    continue
                w = self._pair_weight(node, i, j)
            if w >= _INF:
                return _INF
            if w > 0:
                edges[(i, j)] = w
        node.hedges = edges
        node.hmemo = None
        return self._cover_memo(node)["total"]

    @staticmethod
    def _cover_memo(node: CTNode) -> dict:
        """The node's weighted conflict graph covered per component: ``{"total": value, "where":
        {agent: (component edges, component value)}}``, plus child bounds as they get computed."""
        memo = node.hmemo
        if memo is None:
            total, where = 0, {}
            for comp, cedges, val in _mvc_components(node.hedges or {}):
                total += val
                for v in comp:
                    where[v] = (cedges, val)
            memo = node.hmemo = {"total": total, "where": where}
        return memo

    def _child_bound(self, node: CTNode, i: int, cons, forced: bool) -> Tuple[int, int]:
        """``(g, f)`` lower bounds of the child that adds ``cons`` to local agent ``i``.

        A forced branch raises the agent's cost by some ``d >= 1`` (more after a length
        constraint); every edge ``(i, x)`` of the weighted conflict graph then still needs at
        least its weight minus ``d`` (the pair's cost cannot drop, agent ``i``'s own cost rose by
        ``d``), and the other edges are unchanged: the minimum vertex cover of that graph bounds
        the child's heuristic.
        """
        if not forced:
            return node.g, node.f
        cost = node.paths[i].cost
        new = cost + 1
        for c in cons:
            if isinstance(c, LengthConstraint) and c.time + 1 > new:
                new = c.time + 1
        d = new - cost
        g = node.g + d
        memo = self._cover_memo(node)
        f = memo.get((i, d))
        if f is None:
            h = memo["total"]
            part = memo["where"].get(i)
            if part is not None:
                cedges, val = part
                if len(cedges) == 1:
                    h += max(0, val - d) - val
                else:
                    h += _min_vertex_cover({e: (w - d if i in e else w) for e, w in cedges.items()}) - val
            f = memo[(i, d)] = max(node.f, g + h)
        return g, f

    # -------------------------------------------------------------- search
    def _root(self) -> Optional[CTNode]:
        m = len(self.agents)
        paths: List[Optional[AgentPath]] = [None] * m
        conflicts: Dict[Tuple[int, int], List[Conflict]] = {}
        for i in range(m):
            if self.init_paths is not None:
                p = self.init_paths[i]
            else:
                p = self._plan(i, self.init_cons[i], paths)
            if p is None:
                return None
            paths[i] = p
            self._detect(i, p, paths, conflicts, upto=i)
        g = sum(p.cost for p in paths)
        root = CTNode(g, paths, list(self.init_cons), conflicts, next(self.ctx.ids))
        return root

    def run(self) -> Tuple[str, Optional[CTNode]]:
        """Search. Returns ``("solved", node)``, ``("infeasible", None)`` or ``("limit", None)``.

        Raises :class:`SearchTimeout` at the deadline; ``self.lower_bound`` always holds the best
        proven lower bound.
        """
        ctx = self.ctx
        stats = ctx.stats
        root = self._root()
        if root is None:
            return "infeasible", None
        if not self.sub:
            stats.hl_generated += 1
        self.lower_bound = root.f
        open_list = [root]
        while open_list:
            node = heapq.heappop(open_list)
            if node.f > self.lower_bound:
                self.lower_bound = node.f
            ctx.check_time()
            if node.pending is not None:
                if self._generate(node):
                    if not self.sub:
                        stats.hl_generated += 1
                    heapq.heappush(open_list, node)
                continue
            if ctx.pair_check_at is not None and not self.sub and _time.perf_counter() > ctx.pair_check_at:
                ctx.pair_check_at = None
                ctx.infeasible_reason = ctx.opt._pair_check()
                if ctx.infeasible_reason is not None:
                    return "infeasible", None
            if not node.h_done and self.heuristic != "none" and node.conflicts:
                h = self._compute_h(node)
                node.h_done = True
                if h >= _INF:
                    continue  # some pair cannot be solved under these constraints
                if node.g + h > node.f:
                    node.h = h
                    node.f = node.g + h
                    heapq.heappush(open_list, node)
                    continue
            if not node.conflicts:
                self.lower_bound = node.g
                return "solved", node
            if self.node_limit is not None and self.expanded >= self.node_limit:
                heapq.heappush(open_list, node)
                self.lower_bound = open_list[0].f
                return "limit", None
            self.expanded += 1
            if not self.sub:
                stats.hl_expanded += 1
            children = self._expand(node)
            if children is None:  # bypass: the node got better paths, look at it again
                heapq.heappush(open_list, node)
                continue
            for child in children:
                if not self.sub and child.pending is None:
                    stats.hl_generated += 1
                heapq.heappush(open_list, child)
        return "infeasible", None

    def _expand(self, node: CTNode) -> Optional[List[CTNode]]:
        """The children of ``node``, or ``None`` when a bypass improved ``node`` itself.

        A branch known to raise its agent's cost (cardinal side) cannot give a bypass, so its
        child is only created (``pending``), with the parent's bound: it is planned when popped,
        which saves the low-level search of every child the search never reaches.
        """
        branches, forced = self._choose_forced(node)
        children = []
        for k, (gid, cons) in enumerate(branches):
            i = self.local[gid]
            new_cons = node.cons[i].add(*cons)
            if forced[k]:
                g, f = self._child_bound(node, i, cons, True)
                child = CTNode(g, None, None, {}, next(self.ctx.ids), node.depth + 1)
                child.n_conflicts = node.n_conflicts
                child.f = f
                child.h = f - g
                child.pending = (node, i, new_cons)
                children.append(child)
                continue
            path = self._plan(i, new_cons, node.paths)
            if path is None:
                continue
            paths = list(node.paths)
            paths[i] = path
            g = node.g - node.paths[i].cost + path.cost
            conflicts = {p: lst for p, lst in node.conflicts.items() if i not in p}
            self._detect(i, path, paths, conflicts)
            if self.use_bypass and g == node.g:
                n_new = sum(len(v) for v in conflicts.values())
                if n_new < node.n_conflicts:
                    # same cost, fewer conflicts, still satisfies the node's constraints: adopt it
                    node.paths = paths
                    node.set_conflicts(conflicts)
                    self.ctx.stats.bypasses += 1
                    return None
            cons_list = list(node.cons)
            cons_list[i] = new_cons
            child = CTNode(g, paths, cons_list, conflicts, next(self.ctx.ids), node.depth + 1)
            if node.f > child.f:  # path-max: a child's bound is at least its parent's
                child.h = node.f - child.g
                child.f = node.f
            children.append(child)
        return children

    def _generate(self, node: CTNode) -> bool:
        """Plan a pending node's path; False if the constraints leave the agent no path."""
        parent, i, new_cons = node.pending
        node.pending = None
        path = self._plan(i, new_cons, parent.paths)
        if path is None:
            return False
        paths = list(parent.paths)
        paths[i] = path
        conflicts = {p: lst for p, lst in parent.conflicts.items() if i not in p}
        self._detect(i, path, paths, conflicts)
        cons_list = list(parent.cons)
        cons_list[i] = new_cons
        node.g = parent.g - parent.paths[i].cost + path.cost
        node.paths = paths
        node.cons = cons_list
        node.set_conflicts(conflicts)
        node.f = max(node.f, node.g)
        node.h = node.f - node.g
        return True


# ---------------------------------------------------------------------------------- ECBS
class _ECBS(_CBS):
    """Bounded-suboptimal ECBS: focal search on both levels with weight ``w``."""

    def __init__(self, ctx: _Context, w: float, target_reasoning: bool, node_limit: Optional[int]):
        m = ctx.inst.n_agents
        super().__init__(ctx, list(range(m)), [EMPTY] * m, heuristic="none", prioritize=False,
                         bypass=False, target_reasoning=target_reasoning, node_limit=node_limit,
                         symmetry=False)
        self.w = w

    def _plan_focal(self, i: int, cons: ConstraintSet, paths, lb_floor: int = 0) -> Optional[AgentPath]:
        ctx = self.ctx
        cc = ctx.compile(i, cons)
        res = Reservation(paths, i, self.inst) if len(paths) > 1 else None
        out = focal_search(self.inst, i, cc, res, self.w, ctx.deadline, ctx.counter)
        if out is None:
            return None
        events, lb = out
        return AgentPath(events, self.inst, lb=max(lb, lb_floor))

    def run_focal(self) -> Tuple[str, Optional[CTNode]]:
        ctx = self.ctx
        stats = ctx.stats
        m = len(self.agents)
        paths: List[Optional[AgentPath]] = [None] * m
        conflicts: Dict[Tuple[int, int], List[Conflict]] = {}
        for i in range(m):
            p = self._plan_focal(i, EMPTY, paths)
            if p is None:
                return "infeasible", None
            paths[i] = p
            self._detect(i, p, paths, conflicts, upto=i)
        root = CTNode(sum(p.cost for p in paths), paths, [EMPTY] * m, conflicts, next(ctx.ids))
        root.lb = sum(p.lb for p in paths)
        stats.hl_generated += 1
        open_lb = [(root.lb, root.id, root)]
        focal = [(root.n_conflicts, root.g, root.id, root)]
        pending: List[Tuple[int, int, CTNode]] = []
        bound = self.w * root.lb
        self.lower_bound = root.lb
        while True:
            ctx.check_time()
            if ctx.pair_check_at is not None and _time.perf_counter() > ctx.pair_check_at:
                ctx.pair_check_at = None
                ctx.infeasible_reason = ctx.opt._pair_check()
                if ctx.infeasible_reason is not None:
                    return "infeasible", None
            while open_lb and open_lb[0][2].closed:
                heapq.heappop(open_lb)
            if not open_lb:
                return "infeasible", None
            lb_min = open_lb[0][0]
            self.lower_bound = max(self.lower_bound, lb_min)
            if self.w * lb_min > bound:
                bound = self.w * lb_min
                while pending and pending[0][0] <= bound:
                    _, _, nd = heapq.heappop(pending)
                    heapq.heappush(focal, (nd.n_conflicts, nd.g, nd.id, nd))
            node = None
            while focal:
                cand = heapq.heappop(focal)[3]
                if not cand.closed:
                    node = cand
                    break
            if node is None:
                # cannot happen (the node with the smallest bound is always in focal); be safe
                bound = max(bound, min(nd.g for _, _, nd in pending)) if pending else bound
                while pending and pending[0][0] <= bound:
                    _, _, nd = heapq.heappop(pending)
                    heapq.heappush(focal, (nd.n_conflicts, nd.g, nd.id, nd))
                continue
            node.closed = True
            if not node.conflicts:
                return "solved", node
            if self.node_limit is not None and self.expanded >= self.node_limit:
                return "limit", None
            self.expanded += 1
            stats.hl_expanded += 1
            for gid, cons in self._choose(node):
                i = gid
                new_cons = node.cons[i].add(*cons)
                path = self._plan_focal(i, new_cons, node.paths, lb_floor=node.paths[i].lb)
                if path is None:
                    continue
                paths = list(node.paths)
                paths[i] = path
                conflicts = {p: lst for p, lst in node.conflicts.items() if i not in p}
                self._detect(i, path, paths, conflicts)
                cons_list = list(node.cons)
                cons_list[i] = new_cons
                child = CTNode(sum(p.cost for p in paths), paths, cons_list, conflicts, next(ctx.ids),
                               node.depth + 1)
                child.lb = max(node.lb, sum(p.lb for p in paths))
                stats.hl_generated += 1
                heapq.heappush(open_lb, (child.lb, child.id, child))
                if child.g <= bound:
                    heapq.heappush(focal, (child.n_conflicts, child.g, child.id, child))
                else:
                    heapq.heappush(pending, (child.g, child.id, child))


# ---------------------------------------------------------------------------------- feasibility
def _pair_feasible(inst: MapfInstance, a: int, b: int) -> bool:
    """Whether agents ``a`` and ``b`` alone can both reach their goals (joint-state search).

    Uses unit-time semantics (vertex, swap, proximity), which every durative plan can be
    serialised into, so ``False`` proves the whole instance infeasible under either model.
    """
    succ = inst.succ
    near = inst.near_mat
    start = (inst.starts[a], inst.starts[b])
    goal = (inst.goals[a], inst.goals[b])
    seen = {start}
    stack = [start]
    while stack:
        x, y = stack.pop()
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


# ---------------------------------------------------------------------------------- solver
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
        time_limit: wall-clock seconds; the search ends with status ``"timeout"``.
        memory_limit_mb: how much the process may grow (resident memory, MiB) during the
            search; past it the search ends with status ``"timeout"`` and a message saying so,
            instead of exhausting the machine's memory (long optimal searches keep every open
            constraint-tree node). ``None`` turns the guard off; where the resident size cannot
            be read (no ``/proc`` and no :mod:`resource`) there is no guard.
        node_limit: high-level expansions; the search ends with status ``"timeout"``.
        pair_node_limit: high-level expansions of each two-agent search of the WDG heuristic
            (past it the pair's lower bound is used, which keeps the heuristic admissible); an
            agent pair whose searches keep reaching it gets half of it each time, down to 8.
        pair_check_states: an exact two-agent feasibility check of every pair (which can prove
            infeasibility) runs before the search when ``pairs * N**2`` is at most this, and
            once the search has run for a second when it is at most 100 times this.
    """

    def __init__(
        self,
        instance,
        starts: Optional[Sequence[int]] = None,
        goals: Optional[Sequence[int]] = None,
        *,
        time_model: str = "unit",
        proximity=None,
        suboptimality: float = 1.0,
        heuristic: str = "wdg",
        prioritize: bool = True,
        bypass: bool = True,
        target_reasoning: bool = True,
        symmetry: bool = True,
        grid_coords=None,
        vanilla: bool = False,
        time_limit: float = 60.0,
        memory_limit_mb: Optional[float] = DEFAULT_MEMORY_LIMIT_MB,
        node_limit: Optional[int] = None,
        pair_node_limit: int = 64,
        pair_check_states: int = 20_000,
    ):
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
        if not (time_limit > 0):
            raise ValueError(f"time_limit must be > 0 seconds, got {time_limit!r}")
        if memory_limit_mb is not None and not (memory_limit_mb > 0):
            raise ValueError(f"memory_limit_mb must be > 0 (or None for no limit), got {memory_limit_mb!r}")
        if node_limit is not None and node_limit < 0:
            raise ValueError(f"node_limit must be >= 0, got {node_limit!r}")
        self.suboptimality = float(suboptimality)
        if vanilla:
            heuristic, prioritize, bypass, target_reasoning, symmetry = "none", False, False, False, False
        self.heuristic = heuristic
        self.prioritize = prioritize
        self.bypass = bypass
        self.target_reasoning = target_reasoning
        self.symmetry = symmetry and prioritize
        self.grid_coords = grid_coords
        if grid_coords is not None:
            GridGeometry(self.instance, grid_coords)  # validate now: a clear error early
        self.time_limit = float(time_limit)
        self.memory_limit_mb = None if memory_limit_mb is None else float(memory_limit_mb)
        self.node_limit = node_limit
        self.pair_node_limit = int(pair_node_limit)
        self.pair_check_states = int(pair_check_states)

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
            return self._pair_check()
        return None

    def _pair_check_size(self) -> int:
        k = self.instance.n_agents
        return k * (k - 1) // 2 * self.instance.n_nodes ** 2

    def _pair_check(self) -> Optional[str]:
        inst = self.instance
        k = inst.n_agents
        for a in range(k):
            for b in range(a + 1, k):
                if not _pair_feasible(inst, a, b):
                    return f"agents {a} and {b} cannot both reach their goals, even ignoring the others"
        return None

    # -------------------------------------------------------------- solve
    def solve(self) -> CBSResult:
        """Run the search and return a :class:`CBSResult` (never raises on a hard instance)."""
        # the search allocates many small long-lived objects; with the default thresholds the
        # cyclic garbage collector keeps rescanning them (about a fifth of the run time), so it
        # runs less often during the search (the thresholds are restored afterwards)
        old = gc.get_threshold()
        gc.set_threshold(max(old[0], 100_000), max(old[1], 50), max(old[2], 100))
        try:
            return self._solve()
        finally:
            gc.set_threshold(*old)

    def _solve(self) -> CBSResult:
        t0 = _time.perf_counter()
        inst = self.instance
        ctx = _Context(inst, t0 + self.time_limit, self)
        stats = ctx.stats
        result: CBSResult

        def finish(res: CBSResult) -> CBSResult:
            stats.ll_expanded = ctx.counter.expanded
            stats.ll_calls = ctx.counter.calls
            stats.runtime_s = _time.perf_counter() - t0
            res.stats = stats
            res.time_model = inst.time_model
            return res

        if inst.n_agents == 0:
            return finish(CBSResult("optimal", [], 0, 0, 0, message="no agents"))
        reason = self._precheck()
        if reason is not None:
            return finish(CBSResult("infeasible", message=reason))
        w = self.suboptimality
        if w > 1.0:
            search: _CBS = _ECBS(ctx, w, self.target_reasoning, self.node_limit)
        else:
            search = _CBS(ctx, list(range(inst.n_agents)), [EMPTY] * inst.n_agents,
                          heuristic=self.heuristic, prioritize=self.prioritize, bypass=self.bypass,
                          target_reasoning=self.target_reasoning, node_limit=self.node_limit,
                          symmetry=self.symmetry)
        try:
            status, node = search.run_focal() if w > 1.0 else search.run()
        except SearchTimeout:
            lb = search.lower_bound or None
            if ctx.stop_reason == "memory":
                msg = (f"memory limit reached: the search grew the process by more than "
                       f"{self.memory_limit_mb:g} MiB (memory_limit_mb)")
            else:
                msg = f"time limit of {self.time_limit:g} s reached"
            return finish(CBSResult("timeout", lower_bound=lb, message=msg))
        if status == "infeasible":
            msg = ctx.infeasible_reason or "the constraint tree was exhausted: no solution exists"
            return finish(CBSResult("infeasible", message=msg))
        if status == "limit":
            return finish(CBSResult("timeout", lower_bound=search.lower_bound or None,
                                    message=f"node limit of {self.node_limit} expansions reached"))
        paths = [list(p.events) for p in node.paths]
        soc = sum(p.cost for p in node.paths)
        makespan = max(p.cost for p in node.paths)
        if w > 1.0:
            lb = min(search.lower_bound, soc)
            st = "optimal" if lb >= soc else "suboptimal"
            msg = f"cost within {w:g} x optimal" if st == "suboptimal" else "cost equals the proven lower bound"
        else:
            lb, st, msg = soc, "optimal", "optimal sum of costs"
        return finish(CBSResult(st, paths, soc, makespan, lb, message=msg))


def solve_cbs(
    graph,
    starts: Sequence[int],
    goals: Sequence[int],
    *,
    time_model: str = "unit",
    proximity=None,
    suboptimality: float = 1.0,
    time_limit: float = 60.0,
    node_limit: Optional[int] = None,
    vanilla: bool = False,
    **options,
) -> CBSResult:
    """Solve a multi-agent path finding instance with CBS (or ECBS if ``suboptimality > 1``).

    ``graph`` holds edge durations (scipy sparse / dense matrix or adjacency list); see
    :class:`CBSSolver` for the options. Returns a :class:`CBSResult`; raises ``ValueError``
    only for malformed input (bad node ids, duplicate starts or goals, bad durations).
    """
    return CBSSolver(graph, starts, goals, time_model=time_model, proximity=proximity,
                     suboptimality=suboptimality, time_limit=time_limit, node_limit=node_limit,
                     vanilla=vanilla, **options).solve()
