"""Conflict classification in the optimal CBS search: MDDs, whether a constraint must raise an
agent's cost, cardinal / semi-cardinal / non-cardinal conflicts, and the symmetric splits
(corridor, pseudo-corridor and rectangle reasoning of :mod:`agents.search.mapf.symmetry`).

:class:`ConflictClassification` is that part of :class:`agents.search.mapf.cbs.CBSSearch`
(which derives from it).
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple

from .conflicts import CARDINAL, EDGE, NON_CARDINAL, SEMI_CARDINAL, VERTEX, Conflict, SymmetricSplit
from .constraints import FOREVER, Constraint, EdgeConstraint, LengthConstraint, RangeConstraint, VertexConstraint
from .context import SearchContext
from .ctnode import CTNode
from .heuristics import ANCESTORS
from .instance import MapfInstance
from .lowlevel import earliest_arrival
from .mdd import MDD, build_mdd, prune_mdd


class ConflictClassification:
    """MDDs and conflict classification of the CBS search; the search provides the attributes
    below and :meth:`_members` (a local agent's meta-agent)."""

    ctx: SearchContext
    inst: MapfInstance
    agents: List[int]
    local: Dict[int, int]
    tr: bool
    pseudo_corridors: bool

    def _members(self, node: CTNode, i: int) -> Tuple[int, ...]:
        """The local agents planned together with local agent ``i``; provided by the search."""
        raise NotImplementedError

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
        # a member of a meta-agent has no MDD of its own: its side is not known to raise the cost
        c.card1 = len(self._members(node, l1)) == 1 and self._raises_cost(node, l1, cons1)
        c.card2 = len(self._members(node, l2)) == 1 and self._raises_cost(node, l2, cons2)
        c.cls = CARDINAL if (c.card1 and c.card2) else (SEMI_CARDINAL if (c.card1 or c.card2) else NON_CARDINAL)
        return c.cls

    def _symmetric_split(self, node: CTNode, c: Conflict) -> Optional[SymmetricSplit]:
        """A corridor, pseudo-corridor or rectangle split for ``c``: ``(class, branches, forced,
        kind)``, or ``None``."""
        ctx = self.ctx
        if c.kind not in (VERTEX, EDGE):
            return None
        l1, l2 = self.local[c.a1], self.local[c.a2]
        if len(self._members(node, l1)) > 1 or len(self._members(node, l2)) > 1:
            return None  # the splits read the agents' own MDDs
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
            kind = "corridor"
            if br is None and self.pseudo_corridors:
                br = corridors.pseudo_split(c, c.a1, self._mdd(node, l1), c.a2, self._mdd(node, l2), earliest)
                kind = "pseudo"
            if br is not None:
                cards = []
                for gid, cons in br:
                    i = self.local[gid]
                    rc = cons[0]
                    assert isinstance(rc, RangeConstraint)  # corridor splits are range constraints
                    m = self._mdd(node, i)
                    cards.append(not m.avoidable(rc.node, rc.start, True, rc.end))
                cls = CARDINAL if all(cards) else (SEMI_CARDINAL if any(cards) else NON_CARDINAL)
                return cls, br, tuple(cards), kind
        geom = ctx.geometry
        if geom is not None and c.kind == VERTEX:
            br = geom.split(c, c.a1, self._mdd(node, l1), c.a2, self._mdd(node, l2))
            if br is not None:
                return CARDINAL, br, (True, True), "rectangle"
        return None


__all__ = ["ConflictClassification"]
