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

from itertools import combinations
from typing import Dict, List, Optional, Sequence, Set, Tuple

from .conflicts import CARDINAL, Conflict
from .constraints import Constraint, LengthConstraint
from .context import SearchContext
from .coupled import CoupledLimit, coupled_astar
from .ctnode import CoverMemo, CTNode
from .instance import MapfInstance
from .mdd import MDD, mdds_dependent
from .paths import AgentPath, satisfies

#: The weight (and heuristic) of an agent pair that cannot be solved under its constraints.
INFEASIBLE = 1 << 50
#: how many constraint-set ancestors are searched for a pair result to reuse
ANCESTORS = 8
#: components of the conflict graph up to this many vertices are covered exactly
_EXACT_COVER_MAX = 12
#: child bounds: a component with more vertices than this is not covered again per branch (its
#: cover minus the cost rise is taken; see ``_child_bound``)
_CHILD_COVER_MAX = 64
#: group bounds: candidate groups looked at per node at most (scored, the best are evaluated)
_GROUP_CANDIDATES_MAX = 2_000
#: group bounds: coupled searches may always expand this many states in a solve
GROUP_BASE_STATES = 50_000

#: Weighted conflict graph: ``{(i, j): weight}``, plus group constraints ``{(i, j, k, ...): weight}``
#: (keys of three or more agents: the group's extra cost, see :func:`min_vertex_cover`).
Edges = Dict[Tuple[int, ...], int]

# ---------------------------------------------------------------------------------- vertex cover
#: component covers by canonical form (the same shape under other agent ids)
_mvc_cache: Dict[Tuple[Tuple[Tuple[int, ...], int], ...], int] = {}
#: whole covers by their edges in dict order (a tuple, which the garbage collector stops tracking):
#: the child bounds of the f-aware conflict choice ask for the same reduced graphs again and again
#: (about 95% hits on room-32-32-4), and this key costs far less than splitting the graph into
#: components and putting each in canonical form
_cover_cache: Dict[Tuple[Tuple[Tuple[int, ...], int], ...], int] = {}


def min_vertex_cover(edges: Edges) -> int:
    """Edge-weighted minimum vertex cover: min sum x_v with x_i + x_j >= w_ij, x >= 0 integers.

    A key of three or more vertices is a group constraint ``sum_{v in key} x_v >= w`` (a
    hyperedge); the value is then the minimum over the same integers meeting every pair and
    every group constraint at once. Exact per connected component up to 12 vertices (branch and
    bound, cached by component); larger components use a packing lower bound (the weights of
    constraints with pairwise disjoint vertices, picked greedily; still admissible).
    """
    if not edges:
        return 0
    key = tuple(edges.items())
    val = _cover_cache.get(key)
    if val is None:
        val = sum(v for _, _, v in mvc_components(edges))
        if len(_cover_cache) > 100_000:
            _cover_cache.clear()
        _cover_cache[key] = val
    return val


def mvc_components(edges: Edges) -> List[Tuple[List[int], Edges, int]]:
    """Per connected component of the positive-weight edges: ``(vertices, edges, cover value)``.

    A group constraint joins all its vertices into one component.
    """
    adj: Dict[int, Dict[int, int]] = {}
    hyper: List[Tuple[Tuple[int, ...], int]] = []
    link: Dict[int, set] = {}
    for e, w in edges.items():
        if w <= 0:
            continue
        if len(e) == 2:
            i, j = e
            adj.setdefault(i, {})[j] = max(w, adj.get(i, {}).get(j, 0))
            adj.setdefault(j, {})[i] = max(w, adj.get(j, {}).get(i, 0))
        else:
            members = tuple(sorted(e))
            hyper.append((members, w))
            for v in members:
                adj.setdefault(v, {})
                link.setdefault(v, set()).update(members)
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
            for u in list(adj[v]) + list(link.get(v, ())):
                if u not in seen:
                    seen.add(u)
                    stack.append(u)
        comp.sort()
        inside = set(comp)
        cpairs = tuple(sorted((i, j, w) for i in comp for j, w in adj[i].items() if i < j))
        chyper = [(e, w) for e, w in hyper if e[0] in inside]
        cdict: Edges = {(i, j): w for i, j, w in cpairs}
        for e, w in chyper:
            cdict[e] = max(w, cdict.get(e, 0))
        if len(cdict) == 1:
            out.append((comp, cdict, next(iter(cdict.values()))))
            continue
        key = _canonical(comp, cdict)
        val = _mvc_cache.get(key)
        if val is None:
            if len(comp) > _EXACT_COVER_MAX:
                val = _packing_bound(cdict)
            else:
                val = _cover_exact(comp, adj, [(e, w) for e, w in cdict.items() if len(e) > 2])
            if len(_mvc_cache) > 100_000:
                _mvc_cache.clear()
            _mvc_cache[key] = val
        out.append((comp, cdict, val))
    return out


def _canonical(comp: List[int], cedges: Edges) -> Tuple[Tuple[Tuple[int, ...], int], ...]:
    index = {v: k for k, v in enumerate(comp)}
    return tuple(sorted((tuple(sorted(index[v] for v in e)), w) for e, w in cedges.items()))


def _packing_bound(cedges: Edges) -> int:
    """Sum of the weights of greedily chosen constraints whose vertices are pairwise disjoint."""
    used: set = set()
    total = 0
    for e, w in sorted(cedges.items(), key=lambda item: (-item[1], item[0])):
        if not used.intersection(e):
            used.update(e)
            total += w
    return total


def _cover_exact(comp: List[int], adj: Dict[int, Dict[int, int]], hyper: List[Tuple[Tuple[int, ...], int]]) -> int:
    """Exact :func:`min_vertex_cover` of one component, with group constraints if any (branch and bound).

    Vertices are assigned in order; a pair constraint is enforced at its later vertex, a group
    constraint at its last member. Some optimum has every ``x_v`` at most the largest weight of
    a constraint on ``v`` (lowering a larger ``x_v`` to it keeps every constraint met), which
    bounds the values tried.
    """
    order = sorted(comp, key=lambda v: (-len(adj[v]), v))
    pos = {v: k for k, v in enumerate(order)}
    n = len(order)
    nbrs = [[(pos[u], w) for u, w in adj[v].items()] for v in order]
    groups = [(tuple(sorted(pos[v] for v in e)), w) for e, w in hyper]
    maxw = [max([w for _, w in nbrs[k]] + [w for m, w in groups if k in m] + [0]) for k in range(n)]
    closing: List[List[Tuple[Tuple[int, ...], int]]] = [[] for _ in range(n)]
    for m, w in groups:
        closing[m[-1]].append((m, w))
    best = [sum(maxw)]
    x = [0] * n

    def lower(k: int) -> int:
        # every unassigned vertex needs at least the largest residual towards assigned ones ...
        need = [0] * n
        s = 0
        for v in range(k, n):
            nv = 0
            for u, w in nbrs[v]:
                if u < k and w - x[u] > nv:
                    nv = w - x[u]
            need[v] = nv
            s += nv
        if not groups:
            return s
        # ... and the group left furthest from being met by them adds its rest
        extra = 0
        for m, w in groups:
            if m[-1] < k:
                continue
            r = w - sum(x[u] for u in m if u < k)
            part = sum(need[u] for u in m if u >= k)
            if r - part > extra:
                extra = r - part
        return s + extra

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
        for m, w in closing[k]:
            r = w - sum(x[u] for u in m if u != k)
            if r > lo:
                lo = r
        for val in range(lo, max(lo, maxw[k]) + 1):
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
    #: group bounds on (see :meth:`_group_constraints`); their knobs below
    group_bounds: bool = False
    group_max_agents: int = 3
    group_limit: int = 4
    group_node_limit: int = 5_000
    group_budget: float = 1.0
    #: per pair of agents (global ids), how many of the search's splits were on their conflicts
    conflict_counts: Dict[Tuple[int, int], int]

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
        if self.group_bounds and unit and self.heuristic == "wdg":
            extra = self._group_constraints(node, edges)
            if extra is None:
                return INFEASIBLE
            if extra:
                before = min_vertex_cover(edges)
                edges.update(extra)
                node.hedges = edges
                node.hmemo = None
                total = self._cover_memo(node)["total"]
                if total > before:
                    self.ctx.stats.group_raised += 1
                return total
        node.hedges = edges
        node.hmemo = None
        return self._cover_memo(node)["total"]

    # ------------------------------------------------------------------ group bounds
    def _group_constraints(self, node: CTNode, edges: Edges) -> Optional[Edges]:
        """Group constraints for the node's weighted conflict graph (``group_bounds``, unit time).

        Candidates are groups of 3 (up to ``group_max_agents``) single agents connected in the
        node's conflict graph; the ``group_limit`` ones whose pairs the search has split on most
        often are evaluated: a group ``G`` gets the constraint ``sum_{v in G} x_v >= D_G``,
        ``D_G`` being the optimal joint cost of ``G`` alone under the node's constraints (or a
        lower bound on it) minus its members' individual costs (:meth:`_group_extra`), when
        ``D_G`` exceeds the cover of the pair edges inside ``G`` (else it adds nothing).

        Admissibility: let ``x_v`` be what agent ``v`` pays above its individual optimum in a
        solution below this node. Every pair edge is met (``w_ij`` is the pair's extra cost
        alone), and every group constraint too (``G`` alone, under the same constraints, is a
        relaxation of the whole problem: ``sum_{v in G} (c_v + x_v) >= J_G``). So the minimum
        of ``sum x_v`` over all the constraints together (:func:`min_vertex_cover`, exact or a
        lower bound) is at most the solution's extra cost: no weight is counted twice, because
        one ``x_v`` serves every constraint it appears in. In a child whose agent ``i`` rises by
        ``d`` the constraint holds with ``D_G - d`` (:meth:`_child_bound`).

        A group evaluated many times without ever adding a constraint is not tried again.
        Returns ``{group: D_G}`` (empty: none), or ``None`` when a group has no joint plan under
        the node's constraints (the node has no solution).
        """
        ctx = self.ctx
        groups = node.groups
        nb: Dict[int, Set[int]] = {}
        for (i, j) in node.conflicts:
            if groups is not None and (len(groups[i]) > 1 or len(groups[j]) > 1):
                continue
            nb.setdefault(i, set()).add(j)
            nb.setdefault(j, set()).add(i)
        cands: Set[Tuple[int, ...]] = set()
        for j in sorted(nb):
            for a, b in combinations(sorted(nb[j]), 2):
                cands.add(tuple(sorted((a, j, b))))
                if len(cands) >= _GROUP_CANDIDATES_MAX:
                    break
        size = 3
        while size < self.group_max_agents and len(cands) < _GROUP_CANDIDATES_MAX:
            size += 1
            for g in sorted(c for c in cands if len(c) == size - 1):
                for v in sorted(set().union(*(nb[u] for u in g)) - set(g)):
                    cands.add(tuple(sorted(g + (v,))))
        if not cands:
            return {}
        counts = self.conflict_counts
        agents = self.agents
        scored = []
        for g in cands:
            gids = tuple(sorted(agents[i] for i in g))
            use = ctx.group_use.get(gids)
            if use is not None and use[0] >= 4 * (use[1] + 2):
                continue
            splits = sum(counts.get((a, b), 0) for a, b in combinations(gids, 2))
            inner = sum(1 for a, b in combinations(g, 2) if (a, b) in node.conflicts)
            scored.append((-splits, -inner, gids, g))
        scored.sort()
        out: Edges = {}
        for _, _, gids, g in scored[:self.group_limit]:
            delta = self._group_extra(node, g)
            if delta >= INFEASIBLE:
                return None
            use = ctx.group_use.setdefault(gids, [0, 0])
            use[0] += 1
            inside = {e: w for e, w in edges.items() if all(v in g for v in e)}
            if delta > 0 and delta > min_vertex_cover(inside):
                use[1] += 1
                ctx.stats.group_constraints += 1
                out[g] = delta
        return out

    def _group_extra(self, node: CTNode, g: Tuple[int, ...]) -> int:
        """``D_G``: a lower bound on the optimal joint cost of the local agents ``g`` alone under
        the node's constraints minus their individual costs (``INFEASIBLE``: no joint plan).

        The joint cost is memoised by the members' constraint contents; under more constraints
        it cannot drop, and (as for pairs) an ancestor's optimal joint plan that meets the
        constraints added since is still optimal. Otherwise the coupled search of
        :mod:`agents.search.mapf.coupled` runs with at most ``group_node_limit`` expansions (at
        the limit its ``f`` bound is used), while the group searches of the solve have expanded
        at most :data:`GROUP_BASE_STATES` plus ``group_budget`` times the other low-level
        expansions; past that only known values and ancestors' bounds are used.
        """
        ctx = self.ctx
        gids = tuple(self.agents[i] for i in g)
        contents = tuple(node.cons[i].content for i in g)
        key = (gids, contents)
        known = ctx.group_costs.get(key)
        if known is None:
            floor = 0
            for m, i in enumerate(g):
                cur = node.cons[i]
                walked: List[Constraint] = []
                for _ in range(ANCESTORS):
                    if cur.parent is None or cur.constraint is None:
                        break
                    walked.append(cur.constraint)
                    cur = cur.parent
                    old = ctx.group_costs.get((gids, contents[:m] + (cur.content,) + contents[m + 1:]))
                    if old is None:
                        continue
                    floor = max(floor, old[0])  # more constraints: the optimum cannot drop
                    if old[1] is not None and all(satisfies(old[1][m], c) for c in walked):
                        known = old
                        ctx.stats.group_reuses += 1
                        break
                if known is not None:
                    break
            if known is None:
                others = ctx.counter.expanded - ctx.group_expanded
                if ctx.group_expanded > GROUP_BASE_STATES + self.group_budget * others:
                    return max(0, floor - sum(node.paths[i].cost for i in g)) if floor < INFEASIBLE else INFEASIBLE
                ccs = [ctx.compile(gid, node.cons[i]) for gid, i in zip(gids, g)]
                ctx.stats.group_searches += 1
                before = ctx.counter.expanded
                try:
                    out = coupled_astar(self.inst, gids, ccs, None, ctx.deadline, ctx.counter,
                                        self.group_node_limit)
                except CoupledLimit as e:
                    known = (max(e.bound, floor), None)
                else:
                    if out is None:
                        known = (INFEASIBLE, None)
                    else:
                        paths = tuple(AgentPath(ev, self.inst) for ev in out)
                        known = (sum(p.cost for p in paths), paths)
                finally:
                    ctx.group_expanded += ctx.counter.expanded - before
            if len(ctx.group_costs) > 100_000:
                ctx.group_costs.clear()
            ctx.group_costs[key] = known
        total = known[0]
        if total >= INFEASIBLE:
            return INFEASIBLE
        return max(0, total - sum(node.paths[i].cost for i in g))

    @staticmethod
    def _cover_memo(node: CTNode) -> CoverMemo:
        """The node's weighted conflict graph covered per component: ``{"total": value, "where":
        {agent: (component edges, component value, vertex count)}}``, plus child bounds as they
        get computed."""
        memo = node.hmemo
        if memo is None:
            total = 0
            where: Dict[int, Tuple[Edges, int, int]] = {}
            for comp, cedges, val in mvc_components(node.hedges or {}):
                total += val
                size = len(comp)
                for v in comp:
                    where[v] = (cedges, val, size)
            memo = node.hmemo = {"total": total, "where": where}
        return memo

    def _child_bound(self, node: CTNode, i: int, cons: Sequence[Constraint], forced: bool) -> Tuple[int, int]:
        """``(g, f)`` lower bounds of the child that adds ``cons`` to local agent ``i``.

        A forced branch raises the agent's cost by some ``d >= 1`` (more after a length
        constraint); every edge ``(i, x)`` of the weighted conflict graph then still needs at
        least its weight minus ``d`` (the pair's cost cannot drop, agent ``i``'s own cost rose by
        ``d``), and the other edges are unchanged: the minimum vertex cover of that graph bounds
        the child's heuristic. It is at least the component's cover minus ``d`` (raising ``x_i``
        by ``d`` turns a cover of the reduced graph into one of the old), which is what a
        component of more than ``_CHILD_COVER_MAX`` vertices gets: covering such a reduced graph
        again (a packing bound, past 12 vertices) for every branch looked at costs seconds per
        conflict choice with hundreds of agents. Smaller components are covered again: on
        room-32-32-4 random-4 (30 agents, components of up to about 20) the packing bound of
        the reduced graph is often the larger, and taking the cover minus ``d`` there instead
        left it unsolved at 60 s (18,093 expansions, bound 981) where it is solved after 23,362.
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
                cedges, val, size = part
                if len(cedges) == 1 or size > _CHILD_COVER_MAX:
                    h += max(0, val - d) - val
                else:
                    h += min_vertex_cover({e: (w - d if i in e else w) for e, w in cedges.items()}) - val
            f = memo[(i, d)] = max(node.f, g + h)
        return g, f
