"""Planning with conflicts allowed: a table of planned paths, and the least conflicting path.

:class:`ConflictTable` holds the planned paths of an instance's agents and answers which agents a
path, a move or a wait conflicts with, with the conflict rules of
:func:`~agents.search.mapf.validate.validate` (durative edges occupy both ends, proximity through
the instance's near lists, agents parked at their goal for good, swaps under unit time).
:func:`soft_sipp` finds one agent's path that conflicts with few of them (none where it can),
the low level of the large-neighbourhood repair (:mod:`agents.search.mapf.lns`) and of
prioritised planning's soft fallback (:func:`~agents.search.mapf.prioritized.plan_in_order`).
"""
from __future__ import annotations

import heapq
from bisect import bisect_right
from typing import Dict, FrozenSet, List, Optional, Sequence, Set, Tuple

from .instance import UNREACHABLE, MapfInstance
from .sipp import FOREVER, BudgetExceeded, Events, NodeRanges

_EMPTY: FrozenSet[int] = frozenset()
#: A node's timeline cut into maximal ranges with the same agents: ``(firsts, lasts, agents)``.
Segments = Tuple[List[int], List[int], List[FrozenSet[int]]]
#: The segments of a node no agent ever occupies (shared).
_FREE: Segments = ([0], [FOREVER], [_EMPTY])


def occupancy(events: Sequence[Tuple[int, int]], unit: bool) -> Tuple[List[Tuple[int, int, int]],
                                                                      List[Tuple[int, int, int]]]:
    """What an agent following ``events`` (then parked at its last node for good) occupies.

    Returns ``(spans, moves)``: ``spans`` are ``(node, first, last)`` inclusive ranges of steps
    (durative: during step ``[k, k + 1)`` the node waited at, or both ends of the edge being
    traversed; unit: the node at time ``k``); ``moves`` are the unit-time moves ``(u, v, t)``
    (leaving ``u`` at ``t``), which conflict with a move ``(v, u, t)`` (a swap).
    """
    spans: List[Tuple[int, int, int]] = []
    moves: List[Tuple[int, int, int]] = []
    for (u, t0), (v, t1) in zip(events, events[1:]):
        spans.append((u, t0, t1 - 1))
        if u != v:
            if unit:
                moves.append((u, v, t0))
            else:
                spans.append((v, t0, t1 - 1))
    g, t_end = events[-1]
    spans.append((g, t_end, FOREVER))
    return spans, moves


class ConflictTable(NodeRanges[Segments]):
    """The planned paths of an instance's agents, and which agents a path or a move conflicts with.

    Every occupied range of steps is recorded at its node and at the nodes near it, tagged with
    its agent, so that an agent at a node conflicts with the agents recorded there at the same
    step. :meth:`segments` cuts a node's timeline where the set of agents there changes;
    :func:`soft_sipp` searches over those segments.

    Args:
        inst: the instance (graph, time model, proximity).
    """

    def __init__(self, inst: MapfInstance) -> None:
        super().__init__(inst)
        #: unit time: ``(u, v) -> {t: agents leaving u for v at t}``
        self._moves: Dict[Tuple[int, int], Dict[int, Set[int]]] = {}
        self._agent_moves: Dict[int, List[Tuple[int, int, int]]] = {}
        #: the paths in the table, by agent
        self.paths: Dict[int, Events] = {}

    def reserve(self, agent: int, events: Events) -> None:
        """Record ``agent``'s path (``[(node, time), ...]``, then parked at its last node)."""
        if agent in self.paths:
            raise ValueError(f"agent {agent} already has a path in the table")
        self.paths[agent] = events
        spans, moves = occupancy(events, self.unit)
        for node, first, last in spans:
            self._block(agent, False, node, first, last)
        for u, v, t in moves:
            self._moves.setdefault((u, v), {}).setdefault(t, set()).add(agent)
        self._agent_moves[agent] = moves

    def remove(self, agent: int) -> Events:
        """Drop ``agent``'s path from the table and return it."""
        events = self.paths.pop(agent)
        self._drop(agent, False)
        for u, v, t in self._agent_moves.pop(agent):
            at = self._moves[(u, v)]
            at[t].discard(agent)
            if not at[t]:
                del at[t]
            if not at:
                del self._moves[(u, v)]
        return events

    # ------------------------------------------------------------------ queries
    def agents_at(self, node: int) -> Set[int]:
        """The agents recorded at ``node`` (or near it) at any time."""
        return {e[2] for e in self._ranges[node]}

    def segments(self, node: int) -> Segments:
        """``node``'s timeline cut into maximal ranges in which the same agents are there:
        ``(firsts, lasts, agents)``, the first range starting at 0, the last one ending at
        ``FOREVER``."""
        seg = self._cache[node]
        if seg is not None:
            return seg
        entries = self._ranges[node]
        if not entries:
            self._cache[node] = _FREE
            return _FREE
        changes: List[Tuple[int, int, int]] = []
        for first, last, agent, _ in entries:
            changes.append((first, 1, agent))
            if last < FOREVER:
                changes.append((last + 1, -1, agent))
        changes.sort()
        count: Dict[int, int] = {}
        firsts: List[int] = []
        lasts: List[int] = []
        sets: List[FrozenSet[int]] = []
        cur_first, cur = 0, _EMPTY
        i, n_changes = 0, len(changes)
        while i < n_changes:
            t = changes[i][0]
            while i < n_changes and changes[i][0] == t:
                _, delta, agent = changes[i]
                count[agent] = count.get(agent, 0) + delta
                i += 1
            now = frozenset(a for a, c in count.items() if c > 0)
            if now != cur:
                if t > cur_first:
                    firsts.append(cur_first)
                    lasts.append(t - 1)
                    sets.append(cur)
                cur_first, cur = t, now
        firsts.append(cur_first)
        lasts.append(FOREVER)
        sets.append(cur)
        seg = (firsts, lasts, sets)
        self._cache[node] = seg
        return seg

    def conflicts(self, events: Events, agent: Optional[int] = None) -> Set[int]:
        """The agents in the table (other than ``agent``) that an agent following ``events``
        (then parked at its last node) would conflict with, as
        :func:`~agents.search.mapf.validate.validate` counts conflicts."""
        spans, moves = occupancy(events, self.unit)
        return self._met(spans, moves, agent)

    def move_conflicts(self, u: int, v: int, t: int) -> Set[int]:
        """The agents that a move ``u -> v`` leaving at ``t`` (a wait if ``u == v``) conflicts
        with: during the move (durative: at both ends over its duration; unit: a swap) and on
        arrival at ``v``. Raises ``ValueError`` if there is no such edge."""
        d = self.inst.duration(u, v)
        if d is None:
            raise ValueError(f"no edge {u} -> {v}")
        if self.unit:
            return self._met([(v, t + 1, t + 1)], [(u, v, t)] if u != v else [], None)
        return self._met([(u, t, t + d - 1), (v, t, t + d)], [], None)

    def _met(self, spans: List[Tuple[int, int, int]], moves: List[Tuple[int, int, int]],
             agent: Optional[int]) -> Set[int]:
        found: Set[int] = set()
        for node, lo, hi in spans:
            for first, last, other, _ in self._ranges[node]:
                if first <= hi and last >= lo:
                    found.add(other)
        for u, v, t in moves:
            found |= self._moves.get((v, u), {}).get(t, set())
        if agent is not None:
            found.discard(agent)
        return found


def soft_sipp(inst: MapfInstance, agent: int, table: ConflictTable, budget: Optional[int] = None,
              counter: Optional[List[int]] = None, limit: Optional[int] = None) -> Optional[Events]:
    """A path of ``agent`` that conflicts with few agents of ``table`` (none if it can), then early.

    A best-first search over ``(node, segment)`` states, where a node's segments are the maximal
    ranges of time in which the same agents of ``table`` are there (:meth:`ConflictTable.segments`):
    safe-interval path planning (:func:`~agents.search.mapf.sipp.sipp`) with every range allowed
    at a price. A label holds its arrival time and the set of agents its path has met (exactly
    those :meth:`ConflictTable.conflicts` would count); labels are expanded fewest agents first,
    then by arrival plus the true distance to the goal, and arriving at the goal adds the agents
    that come to the goal later (the agent stays there). Two shortcuts keep the search small, at
    the price of not always finding the fewest: a state keeps only the labels that no other
    label of it beats in both arrival and number of agents met, and a move leaves later than
    its earliest departure only into a range where it meets no one new, or to meet fewer than
    every earlier departure. Where a conflict-free path exists, the result is one, and it
    arrives when :func:`~agents.search.mapf.sipp.sipp`'s does; on the small graphs of the tests
    the result also meets the fewest agents.

    ``counter`` (a one-element list) accumulates expansions; past ``budget`` the search raises
    :class:`~agents.search.mapf.sipp.BudgetExceeded`; past ``limit`` expansions of this call it
    returns ``None``, as when the goal cannot be reached at all.
    """
    s, g = inst.starts[agent], inst.goals[agent]
    h = inst.h[agent]
    if h[s] >= UNREACHABLE:
        return None
    unit = table.unit
    segments = table.segments
    cache = table._cache  # filled in by ``segments``
    out = table.out
    moves = table._moves
    N = inst.n_nodes
    count = counter if counter is not None else [0]
    stop = None if limit is None else count[0] + limit
    ga, _, gs = segments(g)
    later_at_goal: List[FrozenSet[int]] = [_EMPTY] * len(ga)  # agents at the goal after each segment
    later: FrozenSet[int] = _EMPTY
    for j in range(len(ga) - 1, -1, -1):
        later_at_goal[j] = later
        later = later | gs[j]
    # labels, in parallel lists
    l_node: List[int] = []
    l_seg: List[int] = []
    l_met: List[FrozenSet[int]] = []
    l_t: List[int] = []
    l_parent: List[int] = []
    l_dep: List[int] = []
    l_wait: List[bool] = []
    alive: List[bool] = []
    fronts: Dict[int, List[Tuple[int, int, int]]] = {}  # state code -> its labels' (arrival, agents met, id)
    heap: List[Tuple[int, int, int, int, int]] = []
    push, pop = heapq.heappush, heapq.heappop

    def add(node: int, j: int, met: FrozenSet[int], c: int, t: int, parent: int, dep: int, wait: bool) -> None:
        code = j * N + node
        front = fronts.get(code)
        if front is None:
            front = fronts[code] = []
        elif front:
            for ft, fc, _ in front:
                if ft <= t and fc <= c:
                    return
            kept = []
            for e in front:
                if t <= e[0] and c <= e[1]:
                    alive[e[2]] = False
                else:
                    kept.append(e)
            front[:] = kept
        lid = len(l_node)
        l_node.append(node)
        l_seg.append(j)
        l_met.append(met)
        l_t.append(t)
        l_parent.append(parent)
        l_dep.append(dep)
        l_wait.append(wait)
        alive.append(True)
        front.append((t, c, lid))
        push(heap, (c, t + h[node], -t, 1, lid))

    first = segments(s)[2][0]
    add(s, 0, first, len(first), 0, -1, 0, False)
    while heap:
        _, _, _, kind, lid = pop(heap)
        if kind == 0:
            return _soft_events(lid, l_node, l_t, l_parent, l_dep, l_wait)
        if not alive[lid]:
            continue
        count[0] += 1
        if budget is not None and count[0] > budget:
            raise BudgetExceeded
        if stop is not None and count[0] > stop:
            return None
        u, j, t_u, met = l_node[lid], l_seg[lid], l_t[lid], l_met[lid]
        seg_u = cache[u]
        if seg_u is None:
            seg_u = segments(u)
        ua, ub, us = seg_u
        b_u = ub[j]
        if u == g and not l_wait[lid]:  # park here for good
            push(heap, (len(met | later_at_goal[j]), t_u, -t_u, 0, lid))
        if b_u < FOREVER:  # wait into u's next segment
            new = met | us[j + 1]
            add(u, j + 1, new, len(new), b_u + 1, lid, 0, True)
        n_u = len(ua)
        c_met = len(met)
        for v, d in out[u]:
            if h[v] >= UNREACHABLE:
                continue
            seg_v = cache[v]
            if seg_v is None:
                seg_v = segments(v)
            va, vb, vs = seg_v
            n_v = len(va)
            # departing later than the earliest candidate pays off only by meeting fewer agents
            # (kept only if it meets fewer than every earlier one), or by meeting none (every
            # such arrival is kept, as safe-interval path planning keeps each safe interval)
            fewest = FOREVER
            if unit:
                # at v at t + 1 for a departure t in t_u .. b_u: what it meets changes with v's
                # segment at t + 1 and with swaps
                swaps = moves.get((v, u))
                cands = {t_u}
                jv = 0 if n_v == 1 else bisect_right(va, t_u + 1) - 1
                for x in range(jv + 1, n_v):
                    if va[x] - 1 > b_u:
                        break
                    cands.add(va[x] - 1)
                if swaps:
                    cands.update(x + 1 for x in swaps if t_u <= x < b_u)
                for t in sorted(cands):
                    jt = 0 if n_v == 1 else bisect_right(va, t + 1) - 1
                    new = vs[jt]
                    if swaps and t in swaps:
                        new = new | swaps[t]
                    new = met if new <= met else met | new
                    cn = len(new)
                    if cn == c_met or cn < fewest:
                        add(v, jt, new, cn, t + 1, lid, t, False)
                        fewest = min(fewest, cn)
                continue
            # durative: during the move u and v are occupied over steps t .. t + d - 1, then v
            # from t + d on; what it meets changes where one of v's segments leaves that window
            if n_v == 1 and t_u + d - 1 <= b_u:  # one segment, and u is left within its segment
                only = vs[0]
                new = met if (not only or only <= met) else met | only
                add(v, 0, new, len(new), t_u + d, lid, t_u, False)
                continue
            jv = 0 if n_v == 1 else bisect_right(va, t_u) - 1
            t = t_u
            while True:
                arr = t + d
                k = jv
                new = met
                there = vs[k]
                if there and not there <= new:
                    new = new | there
                while k + 1 < n_v and va[k + 1] <= arr:
                    k += 1
                    there = vs[k]
                    if there and not there <= new:
                        new = new | there
                if arr - 1 > b_u:  # still leaving u after its segment ends
                    x = j + 1
                    while x < n_u and ua[x] <= arr - 1:
                        there = us[x]
                        if there and not there <= new:
                            new = new | there
                        x += 1
                cn = len(new)
                if cn == c_met or cn < fewest:
                    add(v, k, new, cn, arr, lid, t, False)
                    if cn < fewest:
                        fewest = cn
                e = vb[jv]
                if e >= b_u:
                    break
                t = e + 1
                jv += 1
    return None


def _soft_events(lid: int, l_node: List[int], l_t: List[int], l_parent: List[int], l_dep: List[int],
                 l_wait: List[bool]) -> Events:
    """Rebuild ``[(node, time), ...]`` from a label: each arrival, and the departure after a wait."""
    chain = []
    while lid >= 0:
        chain.append(lid)
        lid = l_parent[lid]
    chain.reverse()
    events: Events = [(l_node[chain[0]], 0)]
    for x in chain[1:]:
        if l_wait[x]:
            continue
        u, t_last = events[-1]
        if l_dep[x] > t_last:
            events.append((u, l_dep[x]))
        events.append((l_node[x], l_t[x]))
    return events
