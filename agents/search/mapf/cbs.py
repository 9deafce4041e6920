"""Optimal CBS: the best-first search of the constraint tree and its choice of the conflict to split.

:class:`CBSSearch` runs the high level of optimal CBS: conflicts prioritised (cardinal, then
semi-cardinal, classified with MDDs), bypass, target reasoning, corridor and rectangle splits
(:mod:`agents.search.mapf.symmetry`) and the admissible heuristics of
:mod:`agents.search.mapf.heuristics`. With a heuristic the conflict to split is chosen f-aware:
first the splits whose children get larger lower bounds; a child that must raise its agent's
cost is planned only when it is popped. The same class solves the two-agent sub-problems of
the WDG heuristic. Bounded-suboptimal ECBS is in :mod:`agents.search.mapf.ecbs`.
"""
from __future__ import annotations

import heapq
import time as _time
from typing import List, Optional, Sequence, Tuple, Union

from .conflicts import (
    CARDINAL,
    EDGE,
    NON_CARDINAL,
    SEMI_CARDINAL,
    TARGET,
    VERTEX,
    Branches,
    Conflict,
    SymmetricSplit,
    pair_conflicts,
)
from .constraints import (
    FOREVER,
    Constraint,
    ConstraintSet,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
)
from .context import SearchContext
from .ctnode import ConflictMap, CTNode
from .heuristics import ANCESTORS, INFEASIBLE, ConflictGraphHeuristics
from .lowlevel import earliest_arrival, space_time_astar
from .mdd import MDD, build_mdd, prune_mdd
from .paths import AgentPath, Reservation


class CBSSearch(ConflictGraphHeuristics):
    """One CBS search (the main one, or a two-agent sub-problem of the WDG heuristic).

    ``agents`` are the global ids of the agents it plans (its local agent ``i`` is ``agents[i]``),
    ``init_cons`` their constraint sets at the root; a sub-search starts from ``init_paths``.
    """

    def __init__(self, ctx: SearchContext, agents: List[int], init_cons: List[ConstraintSet], *,
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
    def _plan(self, i: int, cons: ConstraintSet, paths: Sequence[Optional[AgentPath]]) -> Optional[AgentPath]:
        """Local agent ``i``'s cheapest path under ``cons``, fewest conflicts with ``paths``."""
        ctx = self.ctx
        gid = self.agents[i]
        cc = ctx.compile(gid, cons)
        res = Reservation(paths, i, self.inst) if len(paths) > 1 else None
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
                        init_paths=[node.paths[i], node.paths[j]], symmetry=self.symmetry)
        status, best = sub.run()
        return status, best, sub.lower_bound

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
                for _ in range(ANCESTORS):
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

    def _raises_cost(self, node: CTNode, i: int, constraints: Sequence[Constraint]) -> bool:
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

    def _symmetric_split(self, node: CTNode, c: Conflict) -> Optional[SymmetricSplit]:
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
                    assert isinstance(rc, RangeConstraint)  # corridor splits are range constraints
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

    def _choose(self, node: CTNode) -> Branches:
        """The conflict to split on and its branches ``[(agent, constraints), ...]``."""
        return self._choose_forced(node)[0]

    def _choose_forced(self, node: CTNode) -> Tuple[Branches, Tuple[bool, ...]]:
        """:meth:`_choose`, and per branch whether it is known to raise its agent's cost."""
        allc = [c for lst in node.conflicts.values() for c in lst]
        allc.sort(key=lambda c: (c.time, c.a1, c.a2))
        if not self.prioritize:
            return allc[0].branches(self.tr), (False, False)
        for c in allc:
            self._classify(node, c)
        tr = self.tr
        allc.sort(key=lambda c: (c.cls, 0 if (c.kind == TARGET and tr) else 1, c.time, c.a1, c.a2))
        best_key: Optional[Tuple[int, ...]] = None
        best: Optional[Tuple[Union[Branches, Conflict], Tuple[bool, ...]]] = None
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
            if symmetric:
                if not c.sym_done:
                    c.sym = self._symmetric_split(node, c)
                    c.sym_done = True
                sym = c.sym
                if sym is not None:
                    key = (min(sym[0], cls), 0, c.time)
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
        assert best is not None  # there is at least one conflict
        split, forced = best
        if isinstance(split, Conflict):
            return split.branches(self.tr), forced
        return split, forced

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
            if ctx.pair_check_at is not None and not self.sub and _time.perf_counter() > ctx.pair_check_at:
                ctx.pair_check_at = None
                ctx.infeasible_reason = ctx.opt._pair_check()
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
                child = CTNode(g, [], [], {}, next(self.ctx.ids), node.depth + 1)
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

    def _generate(self, node: CTNode, pending: Tuple[CTNode, int, ConstraintSet]) -> bool:
        """Plan a pending node's path; False if the constraints leave the agent no path."""
        parent, i, new_cons = pending
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
