"""Optimal CBS: the best-first search of the constraint tree and its choice of the conflict to split.

:class:`CBSSearch` runs the high level of optimal CBS: conflicts prioritised (cardinal, then
semi-cardinal, classified with MDDs), bypass, target reasoning, corridor and rectangle splits
(:mod:`agents.search.mapf.symmetry`) and the admissible heuristics of
:mod:`agents.search.mapf.heuristics`. With a heuristic the conflict to split is chosen f-aware:
first the splits whose children get larger lower bounds; a child that must raise its agent's
cost is planned only when it is popped. Target conflicts can be split disjointly, and agents
that keep conflicting can be merged into meta-agents (MA-CBS) planned by the coupled search of
:mod:`agents.search.mapf.coupled`. The same class solves the two-agent sub-problems of the WDG
heuristic. Its parts live in one module each: conflict classification and the symmetric splits
in :mod:`agents.search.mapf.classify`, meta-agents in :mod:`agents.search.mapf.merging`, the
heuristics in :mod:`agents.search.mapf.heuristics`. Bounded-suboptimal ECBS is in
:mod:`agents.search.mapf.ecbs`.
"""
from __future__ import annotations

import heapq
from typing import Dict, List, Optional, Sequence, Set, Tuple, Union

from .classify import ConflictClassification
from .conflicts import (
    CARDINAL,
    TARGET,
    Branches,
    Conflict,
    pair_conflicts,
)
from .constraints import (
    FOREVER,
    Constraint,
    ConstraintSet,
    DeadlineConstraint,
    LengthConstraint,
    RangeConstraint,
)
from .context import PAIR_CHECK_MOVES, SearchContext
from .coupled import CoupledLimit
from .ctnode import ConflictMap, CTNode
from .heuristics import INFEASIBLE, ConflictGraphHeuristics
from .lowlevel import space_time_astar
from .merging import MetaAgentMerging
from .paths import AgentPath, Reservation, satisfies

#: A branch's constraints by local agent: ``{i: (its new constraint set, the constraints added)}``.
Changes = Dict[int, Tuple[ConstraintSet, Tuple[Constraint, ...]]]
#: A planned child: ``(paths, constraint sets, g, conflicts, meta-agents)``.
ChildParts = Tuple[List[AgentPath], List[ConstraintSet], int, ConflictMap, Optional[Tuple[Tuple[int, ...], ...]]]


class CBSSearch(MetaAgentMerging, ConflictClassification, ConflictGraphHeuristics):
    """One CBS search (the main one, or a two-agent sub-problem of the WDG heuristic).

    ``agents`` are the global ids of the agents it plans (its local agent ``i`` is ``agents[i]``),
    ``init_cons`` their constraint sets at the root; a sub-search starts from ``init_paths``.

    ``merge_threshold`` (unit time): meta-agent CBS. When the splits on conflicts between two
    (meta-)agents number more than this in the whole search, the node being expanded merges
    them into one meta-agent planned by the coupled search of :mod:`agents.search.mapf.coupled`
    under its members' constraints (``None``: never merge); a coupled search stops after
    ``merge_node_limit`` expansions and that merge is not tried again; no meta-agent grows past
    ``merge_max_agents`` members, nor any whose joint configurations (nodes to the power of
    its members) outnumber ``merge_space_limit`` (``None``: no limit). Coupled searches may
    expand :data:`~agents.search.mapf.merging.MERGE_BASE_STATES` plus ``merge_budget`` times as many states as the other
    low-level searches; past that no merge is made and meta-agents that need replanning are
    split up again. ``disjoint_target``
    (unit time, with target reasoning): split target conflicts disjointly (see
    :meth:`_target_branches`).
    """

    def __init__(self, ctx: SearchContext, agents: List[int], init_cons: List[ConstraintSet], *,
                 heuristic: str, prioritize: bool, bypass: bool, target_reasoning: bool,
                 node_limit: Optional[int], sub: bool = False,
                 init_paths: Optional[List[AgentPath]] = None, symmetry: bool = True,
                 merge_threshold: Optional[int] = None, merge_node_limit: int = 100_000,
                 merge_max_agents: int = 4, merge_budget: float = 0.5, merge_space_limit: Optional[int] = None,
                 disjoint_target: bool = False, pseudo_corridors: bool = False,
                 group_bounds: bool = False, group_max_agents: int = 3, group_limit: int = 4,
                 group_node_limit: int = 5_000, group_budget: float = 1.0):
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
        #: with ``symmetry``: split head-on conflicts outside corridors as pseudo-corridors
        self.pseudo_corridors = pseudo_corridors and symmetry
        #: what the last chosen split was: "plain", "corridor", "pseudo" or "rectangle"
        self.last_split = "plain"
        self.lower_bound = 0
        self.expanded = 0
        #: merge two (meta-)agents once they have conflicted more than this many times (None: never)
        unit = ctx.inst.unit
        self.merge_threshold = merge_threshold if unit else None
        self.merge_node_limit = merge_node_limit
        self.merge_max_agents = merge_max_agents
        self.merge_budget = merge_budget
        self.merge_space_limit = merge_space_limit
        #: low-level expansions of the coupled searches so far
        self.coupled_expanded = 0
        #: split target conflicts disjointly (unit time; see :meth:`_target_branches`)
        self.disjoint_target = disjoint_target and target_reasoning and unit
        #: set when a coupled search proved that some agents cannot all reach their goals at all
        self.proven_infeasible = False
        #: per pair of agents (global ids), how many of the splits so far were on their conflicts
        self.conflict_counts = {}
        #: group bounds in the WDG heuristic (unit time; see the heuristics)
        self.group_bounds = group_bounds and unit and not sub
        self.group_max_agents = group_max_agents
        self.group_limit = group_limit
        self.group_node_limit = group_node_limit
        self.group_budget = group_budget
        #: meta-agents (global ids) whose coupled search ran past ``merge_node_limit``
        self.merge_failed: Set[frozenset] = set()

    # -------------------------------------------------------------- low level
    def _plan(self, i: int, cons: ConstraintSet, paths: Sequence[Optional[AgentPath]]) -> Optional[AgentPath]:
        """Local agent ``i``'s cheapest path under ``cons``, fewest conflicts with ``paths``."""
        ctx = self.ctx
        gid = self.agents[i]
        cc = ctx.compile(gid, cons)
        res = Reservation(paths, i, self.inst, ctx.opt.spread) if len(paths) > 1 else None
        events = space_time_astar(self.inst, gid, cc, res, ctx.deadline, ctx.counter)
        if events is None:
            return None
        return AgentPath(events, self.inst)

    def _detect(self, i: int, path: AgentPath, paths: Sequence[Optional[AgentPath]],
                conflicts: ConflictMap, upto: Optional[int] = None) -> None:
        """Record the conflicts of local agent ``i``'s ``path`` with the other paths (below ``upto``)."""
        gi = self.agents[i]
        inst = self.inst
        for j, pj in enumerate(paths):
            if j == i or pj is None or (upto is not None and j >= upto):
                continue
            found = pair_conflicts(gi, path, self.agents[j], pj, inst)
            if found:
                conflicts[(i, j) if i < j else (j, i)] = found

    def _pair_search(self, node: CTNode, i: int, j: int, node_limit: int) -> Tuple[str, Optional[CTNode], int]:
        """The two-agent CBS of the pair (i, j) under the node's constraints (WDG heuristic)."""
        sub = CBSSearch(self.ctx, [self.agents[i], self.agents[j]], [node.cons[i], node.cons[j]], heuristic="cg",
                        prioritize=True, bypass=True, target_reasoning=self.tr, node_limit=node_limit, sub=True,
                        init_paths=[node.paths[i], node.paths[j]], symmetry=self.symmetry,
                        disjoint_target=self.disjoint_target, pseudo_corridors=self.pseudo_corridors)
        status, best = sub.run()
        return status, best, sub.lower_bound

    def _choose(self, node: CTNode) -> Branches:
        """The conflict to split on and its branches ``[(agent, constraints), ...]``."""
        return self._choose_forced(node)[0]

    def _choose_forced(self, node: CTNode) -> Tuple[Branches, Tuple[bool, ...]]:
        """:meth:`_choose`, and per branch whether it is known to raise its agent's cost."""
        allc = [c for lst in node.conflicts.values() for c in lst]
        allc.sort(key=lambda c: (c.time, c.a1, c.a2))
        self.last_split = "plain"
        if not self.prioritize:
            return self._branches(node, allc[0]), (False, False)
        for c in allc:
            self._classify(node, c)
        tr = self.tr
        allc.sort(key=lambda c: (c.cls, 0 if (c.kind == TARGET and tr) else 1, c.time, c.a1, c.a2))
        best_key: Optional[Tuple[int, ...]] = None
        best: Optional[Tuple[Union[Branches, Conflict], Tuple[bool, ...], str]] = None
        symmetric = self.symmetry and self.inst.unit
        # f-aware choice: with the weighted conflict graph known, prefer the splits whose
        # children get larger lower bounds (see _child_bound), then cardinal ones, etc.
        faware = node.hedges is not None
        for c in allc:
            cls = self._classify(node, c)  # known already (classified above)
            # rank 0: target, corridor or rectangle reasoning; rank 1: a plain split
            key: Tuple[int, ...] = (cls, 0 if (c.kind == TARGET and self.tr) else 1, c.time)
            branches: Optional[Branches] = None
            forced: Tuple[bool, ...] = (c.card1, c.card2)
            kind = "plain"
            if symmetric:
                if not c.sym_done:
                    c.sym = self._symmetric_split(node, c)
                    c.sym_done = True
                sym = c.sym
                if sym is not None:
                    key = (min(sym[0], cls), 0, c.time)
                    branches = sym[1]
                    forced = sym[2]
                    kind = sym[3]
            if faware:
                # (how many children get a larger bound, the smaller and the larger child bound)
                brs = branches if branches is not None else self._branches(node, c)
                fs = [self._child_bound(node, self.local[gid], cons, True)[1] if fc else node.f
                      for (gid, cons), fc in zip(brs, forced)]
                raised = sum(1 for f in fs if f > node.f)
                key = (-raised, -min(fs), -max(fs)) + key
            if best_key is None or key < best_key:
                best_key = key
                best = (branches if branches is not None else c, forced, kind)
                if not faware and key[:2] == (CARDINAL, 0):
                    break
            if not symmetric and not faware and best_key is not None:
                break  # sorted by class and time already
        assert best is not None  # there is at least one conflict
        split, forced, self.last_split = best
        if isinstance(split, Conflict):
            return self._branches(node, split), forced
        return split, forced

    def _branches(self, node: CTNode, c: Conflict) -> Branches:
        """The split of a conflict: :meth:`Conflict.branches`, or :meth:`_target_branches`."""
        if c.kind == TARGET and self.disjoint_target:
            return self._target_branches(node, c)
        return c.branches(self.tr)

    def _target_branches(self, node: CTNode, c: Conflict) -> Branches:
        """The disjoint split of a target conflict: agent ``a1`` (parked at its goal ``x1`` at
        ``t``) makes its final arrival after ``t`` | it arrives at or before ``t`` and then no
        other agent is ever at ``x1`` (or, with proximity, near it) from ``t`` on.

        The second branch is ``DeadlineConstraint(a1, t)``, ``a2`` never again at ``x2`` from
        ``t``, and the same for every other agent whose current path is at a watched node at
        some step from ``t`` on; agents whose paths keep away get no constraint now (if they
        later run into the parked ``a1``, the first branch of that conflict is impossible under
        the deadline and the split is forced). Every solution meets exactly one branch.
        """
        a1, a2, t, x1, x2 = c.a1, c.a2, c.time, c.x1, c.x2
        near = self.inst.near
        watch = [x1] if near is None else [x1] + near[x1]
        second: List[Constraint] = [RangeConstraint(a2, x2, t, FOREVER)]
        for j, p in enumerate(node.paths):
            b = self.agents[j]
            if b == a1 or b == a2:
                continue
            steps = p.steps
            assert steps is not None  # unit time
            later = set(steps[t:]) if t < len(steps) else set()
            later.add(p.goal)
            for y in watch:
                if y in later:
                    second.append(RangeConstraint(b, y, t, FOREVER))
        second.append(DeadlineConstraint(a1, t))
        return [(a1, (LengthConstraint(a1, t),)), (a2, tuple(second))]

    # -------------------------------------------------------------- search
    def _root(self) -> Optional[CTNode]:
        m = len(self.agents)
        paths: List[Optional[AgentPath]] = [None] * m
        conflicts: ConflictMap = {}
        for i in range(m):
            p: Optional[AgentPath]
            if self.init_paths is not None:
                p = self.init_paths[i]
            else:
                p = self._plan(i, self.init_cons[i], paths)
            if p is None:
                return None
            paths[i] = p
            self._detect(i, p, paths, conflicts, upto=i)
        planned = [p for p in paths if p is not None]  # every agent's path, in order
        g = sum(p.cost for p in planned)
        root = CTNode(g, planned, list(self.init_cons), conflicts, next(self.ctx.ids))
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
            pending = node.pending
            if pending is not None:
                if self._generate(node, pending):
                    if not self.sub:
                        stats.hl_generated += 1
                    heapq.heappush(open_list, node)
                continue
            if ctx.pair_check_at is not None and not self.sub and ctx.counter.expanded > ctx.pair_check_at:
                ctx.pair_check_at = None
                ctx.infeasible_reason = ctx.opt._pair_check(PAIR_CHECK_MOVES)
                if ctx.infeasible_reason is not None:
                    return "infeasible", None
            if not node.h_done and self.heuristic != "none" and node.conflicts:
                h = self._compute_h(node)
                node.h_done = True
                if h >= INFEASIBLE:
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
            if self.proven_infeasible:
                return "infeasible", None
            if children is None:  # bypass: the node got better paths, look at it again
                heapq.heappush(open_list, node)
                continue
            for child in children:
                if not self.sub and child.pending is None:
                    stats.hl_generated += 1
                heapq.heappush(open_list, child)
        return "infeasible", None

    def _expand(self, node: CTNode) -> Optional[List[CTNode]]:
        """The children of ``node``, or ``None`` when a bypass or a merge improved ``node`` itself.

        A branch known to raise its agent's cost (cardinal side) cannot give a bypass, so its
        child is only created (``pending``), with the parent's bound: it is planned when popped,
        which saves the low-level search of every child the search never reaches.
        """
        branches, forced = self._choose_forced(node)
        self._count_split(branches)
        if self.merge_threshold is not None:
            merged = self._merge(node, branches)
            if merged == "merged":
                return None
            if merged == "dead":
                return []
        if not self.sub:
            stats = self.ctx.stats
            kind = self.last_split
            if kind == "corridor":
                stats.corridor_splits += 1
            elif kind == "pseudo":
                stats.pseudo_corridor_splits += 1
            elif kind == "rectangle":
                stats.rectangle_splits += 1
        children = []
        for k, (gid, cons) in enumerate(branches):
            i = self.local[gid]
            changes = self._changes(node, cons)
            if forced[k]:
                g, f = self._child_bound(node, i, cons, True)
                child = CTNode(g, [], [], {}, next(self.ctx.ids), node.depth + 1)
                child.n_conflicts = node.n_conflicts
                child.f = f
                child.h = f - g
                child.pending = (node, changes)
                child.groups = node.groups
                children.append(child)
                continue
            parts = self._replan(node, changes)
            if parts is None:
                continue
            paths, cons_list, g, conflicts, groups = parts
            if self.use_bypass and g == node.g and groups is node.groups:
                n_new = sum(len(v) for v in conflicts.values())
                if n_new < node.n_conflicts:
                    # same cost, fewer conflicts, still satisfies the node's constraints: adopt it
                    node.paths = paths
                    node.set_conflicts(conflicts)
                    self.ctx.stats.bypasses += 1
                    return None
            child = CTNode(g, paths, cons_list, conflicts, next(self.ctx.ids), node.depth + 1)
            child.groups = groups
            if node.f > child.f:  # path-max: a child's bound is at least its parent's
                child.h = node.f - child.g
                child.f = node.f
            children.append(child)
        return children

    def _changes(self, node: CTNode, cons: Sequence[Constraint]) -> Changes:
        """A branch's constraints by local agent: ``{i: (new constraint set, added constraints)}``."""
        added: Dict[int, List[Constraint]] = {}
        for c in cons:
            added.setdefault(self.local[c.agent], []).append(c)
        return {i: (node.cons[i].add(*lst), tuple(lst)) for i, lst in added.items()}

    def _replan(self, parent: CTNode, changes: Changes) -> Optional[ChildParts]:
        """Plan a child of ``parent`` that adds ``changes``: ``(paths, constraints, g, conflicts,
        groups)``, or ``None`` when the constraints leave some agent (or meta-agent) no plan.

        Every agent that gets constraints is replanned, with its meta-agent if it has one; under
        unit time an agent whose path meets all its new constraints keeps it (the path is still
        a cheapest one under more constraints).
        """
        cons_list = list(parent.cons)
        for i, (new, _) in changes.items():
            cons_list[i] = new
        paths = list(parent.paths)
        unit = self.inst.unit
        units: List[Tuple[int, ...]] = []
        for i, (_, added) in changes.items():
            if unit and all(satisfies(parent.paths[i], c) for c in added):
                continue
            mem = self._members(parent, i)
            if mem not in units:
                units.append(mem)
        changed: List[int] = []
        groups = parent.groups
        for mem in units:
            if len(mem) > 1:
                try:
                    if not self._merging_affordable():
                        raise CoupledLimit
                    ps = self._plan_group(mem, cons_list, paths)
                except CoupledLimit:
                    # too hard to plan jointly under these constraints (or the coupled searches
                    # have had their share of the work): the members go back to being planned
                    # alone (plain CBS splits resolve their conflicts again)
                    self.merge_failed.add(frozenset(self.agents[i] for i in mem))
                    assert groups is not None  # a group of several members
                    glist = list(groups)
                    for i in mem:
                        glist[i] = (i,)
                    groups = tuple(glist)
                    self.ctx.stats.unmerges += 1
                else:
                    if ps is None:
                        return None
                    for i, p in zip(mem, ps):
                        paths[i] = p
                    changed.extend(mem)
                    continue
            for i in mem:
                alone = self._plan(i, cons_list[i], paths)
                if alone is None:
                    return None
                paths[i] = alone
                changed.append(i)
        g = parent.g + sum(paths[i].cost - parent.paths[i].cost for i in changed)
        conflicts = self._redetect(parent.conflicts, changed, paths)
        return paths, cons_list, g, conflicts, groups

    def _redetect(self, old: ConflictMap, changed: Sequence[int], paths: Sequence[AgentPath]) -> ConflictMap:
        """``old`` without the conflicts of the ``changed`` agents, plus those of their new paths."""
        if len(changed) == 1:
            i = changed[0]
            conflicts = {p: lst for p, lst in old.items() if i not in p}
            self._detect(i, paths[i], paths, conflicts)
            return conflicts
        cset = set(changed)
        conflicts = {p: lst for p, lst in old.items() if p[0] not in cset and p[1] not in cset}
        done: set = set()
        inst = self.inst
        for i in changed:
            gi = self.agents[i]
            for j, pj in enumerate(paths):
                if j == i or j in done:
                    continue
                found = pair_conflicts(gi, paths[i], self.agents[j], pj, inst)
                if found:
                    conflicts[(i, j) if i < j else (j, i)] = found
            done.add(i)
        return conflicts

    def _generate(self, node: CTNode, pending: Tuple[CTNode, Changes]) -> bool:
        """Plan a pending node's paths; False if the constraints leave an agent no path."""
        parent, changes = pending
        node.pending = None
        parts = self._replan(parent, changes)
        if parts is None:
            return False
        paths, cons_list, g, conflicts, groups = parts
        node.groups = groups
        node.g = g
        node.paths = paths
        node.cons = cons_list
        node.set_conflicts(conflicts)
        node.f = max(node.f, node.g)
        node.h = node.f - node.g
        return True
