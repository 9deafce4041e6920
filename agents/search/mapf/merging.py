"""Meta-agents (MA-CBS) in the optimal CBS search: two (meta-)agents that keep conflicting are
planned together by the coupled search of :mod:`agents.search.mapf.coupled`.

:class:`MetaAgentMerging` is the merging part of :class:`agents.search.mapf.cbs.CBSSearch`
(which derives from it): it counts the splits per pair of agents, merges a pair past the
search's ``merge_threshold``, plans meta-agents and keeps the coupled searches within their
budget.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Set, Tuple

from .conflicts import Branches
from .constraints import EMPTY, ConstraintSet
from .context import SearchContext
from .coupled import CoupledLimit, coupled_astar
from .ctnode import ConflictMap, CTNode
from .instance import MapfInstance
from .paths import AgentPath, Reservation

#: coupled searches may always expand this many states in a solve (see ``merge_budget``)
MERGE_BASE_STATES = 250_000


class MetaAgentMerging:
    """Meta-agent merging of the CBS search; the search provides the attributes below and
    :meth:`_redetect`."""

    ctx: SearchContext
    inst: MapfInstance
    agents: List[int]
    local: Dict[int, int]
    sub: bool
    merge_threshold: Optional[int]
    merge_node_limit: int
    merge_max_agents: int
    merge_budget: float
    merge_space_limit: Optional[int]
    coupled_expanded: int
    proven_infeasible: bool
    conflict_counts: Dict[Tuple[int, int], int]
    merge_failed: Set[frozenset]

    def _redetect(self, old: ConflictMap, changed: Sequence[int], paths: Sequence[AgentPath]) -> ConflictMap:
        """``old`` without the conflicts of the ``changed`` agents, plus those of their new paths;
        provided by the search."""
        raise NotImplementedError

    def _members(self, node: CTNode, i: int) -> Tuple[int, ...]:
        """The local agents planned together with local agent ``i`` (``(i,)`` when it is alone)."""
        groups = node.groups
        return (i,) if groups is None else groups[i]

    def _merging_affordable(self) -> bool:
        """Whether coupled searches may still run: they have expanded at most
        ``MERGE_BASE_STATES + merge_budget * (the other low-level expansions)`` states so far."""
        spent = self.coupled_expanded
        others = self.ctx.counter.expanded - spent
        return spent <= MERGE_BASE_STATES + self.merge_budget * others

    def _plan_group(self, members: Tuple[int, ...], cons: Sequence[ConstraintSet],
                    paths: Sequence[Optional[AgentPath]]) -> Optional[List[AgentPath]]:
        """The cheapest joint paths of a meta-agent under its members' constraints (coupled
        search), fewest conflicts with the other ``paths``; ``None`` if there are none.

        Memoised by the members' constraint contents (a remembered plan is still a cheapest one;
        only its conflicts with the other agents may differ)."""
        ctx = self.ctx
        gids = [self.agents[i] for i in members]
        ccs = [ctx.compile(gid, cons[i]) for gid, i in zip(gids, members)]
        key = (tuple(gids), tuple(cons[i].content for i in members))
        if key in ctx.coupled:
            known = ctx.coupled[key]
            if known is None:
                return None
            if isinstance(known, CoupledLimit):
                raise known
            return list(known)
        inside = set(members)
        others = [None if k in inside else p for k, p in enumerate(paths)]
        res = Reservation(others, -1, self.inst) if len(paths) > len(members) else None
        if len(ctx.coupled) > 50_000:
            ctx.coupled.clear()
        before = ctx.counter.expanded
        try:
            out = coupled_astar(self.inst, gids, ccs, res, ctx.deadline, ctx.counter, self.merge_node_limit)
        except CoupledLimit as e:
            ctx.coupled[key] = e
            raise
        finally:
            self.coupled_expanded += ctx.counter.expanded - before
        if out is None:
            ctx.coupled[key] = None
            return None
        planned = [AgentPath(ev, self.inst) for ev in out]
        ctx.coupled[key] = tuple(planned)
        return planned

    def _count_split(self, branches: Branches) -> None:
        """Count a split of two agents' conflict (unit time) in :attr:`conflict_counts`."""
        if len(branches) != 2 or not self.inst.unit:
            return
        a, b = self.agents[self.local[branches[0][0]]], self.agents[self.local[branches[1][0]]]
        if a != b:
            key = (a, b) if a < b else (b, a)
            self.conflict_counts[key] = self.conflict_counts.get(key, 0) + 1

    def _merge(self, node: CTNode, branches: Branches) -> str:
        """Merge the two (meta-)agents of the conflict being split (counted already) once they
        have conflicted more than ``merge_threshold`` times in the search.

        Returns ``"merged"`` (the node now plans them as one meta-agent under the same
        constraints: the same part of the solution space, so it replaces itself), ``"dead"`` (the
        meta-agent has no plan under the node's constraints: nor has the node) or ``"split"``
        (no merge: split as usual). A merge whose coupled search passes ``merge_node_limit``
        expansions is not tried again.
        """
        if len(branches) != 2 or not self.inst.unit:
            return "split"
        a, b = self.agents[self.local[branches[0][0]]], self.agents[self.local[branches[1][0]]]
        if a == b:
            return "split"
        counts = self.conflict_counts  # this split is counted already (_count_split)
        g1, g2 = self._members(node, self.local[a]), self._members(node, self.local[b])
        if g1 == g2:
            return "split"
        total = 0
        for i in g1:
            for j in g2:
                x, y = self.agents[i], self.agents[j]
                total += counts.get((x, y) if x < y else (y, x), 0)
        if self.merge_threshold is None or total <= self.merge_threshold or not self._merging_affordable():
            return "split"
        members = tuple(sorted(g1 + g2))
        if len(members) > self.merge_max_agents:
            return "split"
        if self.merge_space_limit is not None and self.inst.n_nodes ** len(members) > self.merge_space_limit:
            return "split"
        gkey = frozenset(self.agents[i] for i in members)
        if gkey in self.merge_failed:
            return "split"
        ctx = self.ctx
        try:
            if not self.sub and any(len(node.cons[i]) for i in members):
                # first the members alone without constraints (memoised): no joint plan proves
                # the whole instance infeasible
                if self._plan_group(members, [EMPTY] * len(node.cons), node.paths) is None:
                    ids = ", ".join(str(self.agents[i]) for i in members)
                    ctx.infeasible_reason = (
                        f"agents {ids} cannot all reach their goals: every joint plan of these agents makes two of "
                        "them collide (each may reach its goal alone; the other agents aside)")
                    self.proven_infeasible = True
                    return "dead"
            planned = self._plan_group(members, node.cons, node.paths)
        except CoupledLimit:
            self.merge_failed.add(gkey)
            return "split"
        ctx.stats.merges += 1
        if planned is None:
            return "dead"
        paths = list(node.paths)
        for i, p in zip(members, planned):
            paths[i] = p
        groups: List[Tuple[int, ...]] = (list(node.groups) if node.groups is not None
                                         else [(i,) for i in range(len(paths))])
        for i in members:
            groups[i] = members
        node.groups = tuple(groups)
        node.g = node.g + sum(paths[i].cost - node.paths[i].cost for i in members)
        node.set_conflicts(self._redetect(node.conflicts, members, paths))
        node.paths = paths
        node.f = max(node.f, node.g)
        node.h = node.f - node.g
        node.h_done = False
        node.hedges = None
        node.hmemo = None
        return "merged"


__all__ = ["MERGE_BASE_STATES", "MetaAgentMerging"]
