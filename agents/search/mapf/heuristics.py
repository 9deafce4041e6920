"""Admissible high-level heuristics of optimal CBS, from the conflict graph of a CT node.

- ``"cg"``: the cardinal conflict graph (an edge per agent pair with a cardinal conflict);
- ``"dg"``: the dependency graph (also pairs whose MDDs cannot be merged without a conflict);
- ``"wdg"``: the weighted dependency graph, each edge weighted by the extra cost the pair needs,
  from a small two-agent CBS search (memoised by constraint content, reused from an ancestor's
  pair solution where it still meets the constraints).

The heuristic of a node is an edge-weighted minimum vertex cover of its graph
(:func:`min_vertex_cover`: exact per small component, a matching bound on large ones). The
cover also gives the children's bounds before they are planned (:meth:`~ConflictGraphHeuristics._child_bound`),
which the f-aware conflict choice of :mod:`agents.search.mapf.cbs` ranks splits by.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple

from .conflicts import CARDINAL, Conflict
from .constraints import Constraint, LengthConstraint
from .context import SearchContext
from .ctnode import CoverMemo, CTNode
from .instance import MapfInstance
from .mdd import MDD, mdds_dependent
from .paths import satisfies

#: The weight (and heuristic) of an agent pair that cannot be solved under its constraints.
INFEASIBLE = 1 << 50
#: how many constraint-set ancestors are searched for a pair result to reuse
ANCESTORS = 8
#: components of the conflict graph up to this many vertices are covered exactly
_EXACT_COVER_MAX = 12

#: Weighted conflict graph: ``{(i, j): weight}``.
Edges = Dict[Tuple[int, int], int]

# ---------------------------------------------------------------------------------- vertex cover
_mvc_cache: Dict[Tuple[Tuple[int, int, int], ...], int] = {}


def min_vertex_cover(edges: Edges) -> int:
    """Edge-weighted minimum vertex cover: min sum x_v with x_i + x_j >= w_ij, x >= 0 integers.

    Exact per connected component up to 12 vertices (branch and bound, cached by component);
    larger components use a matching lower bound (still admissible).
    """
    if not edges:
        return 0
    return sum(val for _, _, val in mvc_components(edges))


def mvc_components(edges: Edges) -> List[Tuple[List[int], Edges, int]]:
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
            val = _mvc_exact(comp, adj) if len(comp) <= _EXACT_COVER_MAX else _matching_bound(cedges)
            if len(_mvc_cache) > 100_000:
                _mvc_cache.clear()
            _mvc_cache[key] = val
        out.append((comp, cdict, val))
    return out


def _canonical(comp: List[int], cedges: Tuple[Tuple[int, int, int], ...]) -> Tuple[Tuple[int, int, int], ...]:
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


# ---------------------------------------------------------------------------------- heuristics
class ConflictGraphHeuristics:
    """The heuristic part of the optimal CBS search (:class:`agents.search.mapf.cbs.CBSSearch`
    derives from it): the node's weighted conflict graph, its cover, and the children's bounds.

    The search provides the attributes below, conflict classification (:meth:`_classify`), MDDs
    (:meth:`_mdd`) and the two-agent sub-search (:meth:`_pair_search`).
    """

    ctx: SearchContext
    inst: MapfInstance
    agents: List[int]
    heuristic: str

    def _classify(self, node: CTNode, c: Conflict) -> int:
        """The conflict's class (cardinal, semi-cardinal, non-cardinal); provided by the search."""
        raise NotImplementedError

    def _mdd(self, node: CTNode, i: int) -> MDD:
        """Local agent ``i``'s MDD under the node's constraints; provided by the search."""
        raise NotImplementedError

    def _pair_search(self, node: CTNode, i: int, j: int, node_limit: int) -> Tuple[str, Optional[CTNode], int]:
        """Solve the pair (i, j) alone under the node's constraints with at most ``node_limit``
        expansions: ``(status, solution node or None, lower bound)``; provided by the search."""
        raise NotImplementedError

    def _pair_cardinal(self, node: CTNode, lst: List[Conflict]) -> bool:
        """Whether one of a pair's conflicts is cardinal."""
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
            walked: List[Constraint] = []
            for _ in range(ANCESTORS):
                if cur.parent is None or cur.constraint is None:
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
            status, best, lower = self._pair_search(node, i, j, limit)
            if status == "limit":
                ctx.pair_limit_hits[(gi, gj)] = hits + 1
            if status == "solved" and best is not None:
                total = best.g
                if self.inst.unit:
                    if len(ctx.pair_solutions) > 200_000:
                        ctx.pair_solutions.clear()
                    ctx.pair_solutions[key] = (total, best.paths[0], best.paths[1])
            elif status == "infeasible":
                total = INFEASIBLE
            else:
                total = lower
            if len(ctx.pairs) > 200_000:
                ctx.pairs.clear()
            ctx.pairs[key] = total
            val = total
        if val >= INFEASIBLE:
            return INFEASIBLE
        return max(0, val - node.paths[i].cost - node.paths[j].cost)

    def _compute_h(self, node: CTNode) -> int:
        """The node's heuristic (``INFEASIBLE`` if some pair has no solution); records its graph."""
        if self.heuristic == "none" or not node.conflicts:
            return 0
        edges: Edges = {}
        unit = self.inst.unit
        groups = node.groups
        for (i, j), lst in node.conflicts.items():
            if groups is not None and (len(groups[i]) > 1 or len(groups[j]) > 1):
                # a meta-agent's members may trade cost among themselves: only its total cost is
                # known not to drop, so pairs with a member give no admissible edge; leaving them
                # out keeps the cover a lower bound
                continue
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
            if w >= INFEASIBLE:
                return INFEASIBLE
            if w > 0:
                edges[(i, j)] = w
        node.hedges = edges
        node.hmemo = None
        return self._cover_memo(node)["total"]

    @staticmethod
    def _cover_memo(node: CTNode) -> CoverMemo:
        """The node's weighted conflict graph covered per component: ``{"total": value, "where":
        {agent: (component edges, component value)}}``, plus child bounds as they get computed."""
        memo = node.hmemo
        if memo is None:
            total = 0
            where: Dict[int, Tuple[Edges, int]] = {}
            for comp, cedges, val in mvc_components(node.hedges or {}):
                total += val
                for v in comp:
                    where[v] = (cedges, val)
            memo = node.hmemo = {"total": total, "where": where}
        return memo

    def _child_bound(self, node: CTNode, i: int, cons: Sequence[Constraint], forced: bool) -> Tuple[int, int]:
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
        gid = self.agents[i]
        for c in cons:
            if isinstance(c, LengthConstraint) and c.agent == gid and c.time + 1 > new:
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
                    h += min_vertex_cover({e: (w - d if i in e else w) for e, w in cedges.items()}) - val
            f = memo[(i, d)] = max(node.f, g + h)
        return g, f
