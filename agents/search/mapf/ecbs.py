"""ECBS: bounded-suboptimal CBS with focal search on both levels.

The high level expands, among the constraint-tree nodes whose cost is within ``w`` times the
smallest lower bound of the open ones, the node with the fewest conflicts; the low level is
:func:`~agents.search.mapf.lowlevel.focal_search` with the same ``w``. The cost of the solution
found is at most ``w`` times the optimum; its lower bound is kept for the result.
"""
from __future__ import annotations

import heapq
from typing import List, Optional, Sequence, Tuple

from .cbs import CBSSearch
from .constraints import EMPTY, ConstraintSet
from .context import PAIR_CHECK_MOVES, SearchContext
from .ctnode import ConflictMap, CTNode
from .lowlevel import focal_search
from .paths import AgentPath, Reservation


class ECBSSearch(CBSSearch):
    """Bounded-suboptimal ECBS: focal search on both levels with weight ``w``."""

    def __init__(self, ctx: SearchContext, w: float, target_reasoning: bool, node_limit: Optional[int]):
        m = ctx.inst.n_agents
        super().__init__(ctx, list(range(m)), [EMPTY] * m, heuristic="none", prioritize=False,
                         bypass=False, target_reasoning=target_reasoning, node_limit=node_limit,
                         symmetry=False)
        self.w = w

    def _plan_focal(self, i: int, cons: ConstraintSet, paths: Sequence[Optional[AgentPath]],
                    lb_floor: int = 0) -> Optional[AgentPath]:
        """Agent ``i``'s path of cost within ``w`` x its optimum, few conflicts with ``paths``."""
        ctx = self.ctx
        cc = ctx.compile(i, cons)
        res = Reservation(paths, i, self.inst, ctx.opt.spread) if len(paths) > 1 else None
        out = focal_search(self.inst, i, cc, res, self.w, ctx.deadline, ctx.counter)
        if out is None:
            return None
        events, lb = out
        return AgentPath(events, self.inst, lb=max(lb, lb_floor))

    def run_focal(self) -> Tuple[str, Optional[CTNode]]:
        """Search. Returns ``("solved", node)``, ``("infeasible", None)`` or ``("limit", None)``.

        Raises :class:`~agents.search.mapf.lowlevel.SearchTimeout` at the deadline;
        ``self.lower_bound`` always holds the best proven lower bound.
        """
        ctx = self.ctx
        stats = ctx.stats
        m = len(self.agents)
        paths: List[Optional[AgentPath]] = [None] * m
        conflicts: ConflictMap = {}
        for i in range(m):
            p = self._plan_focal(i, EMPTY, paths)
            if p is None:
                return "infeasible", None
            paths[i] = p
            self._detect(i, p, paths, conflicts, upto=i)
        planned = [p for p in paths if p is not None]  # every agent's path, in order
        root = CTNode(sum(p.cost for p in planned), planned, [EMPTY] * m, conflicts, next(ctx.ids))
        root.lb = sum(p.lb for p in planned)
        stats.hl_generated += 1
        open_lb = [(root.lb, root.id, root)]
        focal = [(root.n_conflicts, root.g, root.id, root)]
        pending: List[Tuple[int, int, CTNode]] = []
        bound = self.w * root.lb
        self.lower_bound = root.lb
        while True:
            ctx.check_time()
            if ctx.pair_check_at is not None and ctx.counter.expanded > ctx.pair_check_at:
                ctx.pair_check_at = None
                ctx.infeasible_reason = ctx.opt._pair_check(PAIR_CHECK_MOVES)
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
                child_paths = list(node.paths)
                child_paths[i] = path
                conflicts = {p: lst for p, lst in node.conflicts.items() if i not in p}
                self._detect(i, path, child_paths, conflicts)
                cons_list = list(node.cons)
                cons_list[i] = new_cons
                child = CTNode(sum(p.cost for p in child_paths), child_paths, cons_list, conflicts, next(ctx.ids),
                               node.depth + 1)
                child.lb = max(node.lb, sum(p.lb for p in child_paths))
                stats.hl_generated += 1
                heapq.heappush(open_lb, (child.lb, child.id, child))
                if child.g <= bound:
                    heapq.heappush(focal, (child.n_conflicts, child.g, child.id, child))
                else:
                    heapq.heappush(pending, (child.g, child.id, child))
