"""A complete, anytime search over joint configurations with priority inheritance as its
successor generator, in the manner of LaCAM and LaCAM*.

This follows "LaCAM: Search-Based Algorithm for Quick Multi-Agent Pathfinding" (Okumura, AAAI
2023) and "Improving LaCAM for Scalable Eventually Optimal Multi-Agent Pathfinding" (Okumura,
IJCAI 2023).

High level
    A depth-first search over *configurations*, the joint state of all agents at one time step.
    Each high-level node carries a lazily grown tree of low-level constraints ("agent ``i`` goes
    to ``v`` next"), explored breadth first: every time a node is taken up, one more constraint
    set is taken from its tree, the tree grows by the next agent's choices (those compatible with
    the constraints already set), and the successor configuration that satisfies the constraints
    is made by priority inheritance with backtracking (PIBT; see :mod:`agents.search.mapf.pibt`):
    the constrained agents move as told, the others in the node's priority order (an agent's
    priority grows with every step it is away from its goal), an agent in the way of a more
    urgent one pushed off its node. A configuration already seen is not added again: as in
    LaCAM*, the known node is taken up again and the costs-to-come are repaired through the new
    edge (a Dijkstra-like propagation over the edges found so far, which re-points parents).
    Every valid successor of a configuration is eventually made (by the constraint set that fixes
    every agent's move), so the search is *complete*: an instance whose configurations reachable
    from the starts are exhausted without reaching the goals is reported ``"infeasible"``.

    Before a first solution, a search that has gone ``_PATIENCE`` successor generations without
    a configuration closer to the goals (sum of distances) dives again from the starts (the start
    node is taken up again; its next constraint set and fresh tie-breaks lead elsewhere).

Anytime
    After the first solution the search goes on: a node whose cost-to-come plus the heuristic
    reaches the best sum of costs found is dropped; a node that yields nothing new to follow
    yields the turn to the other open nodes. When no node is left the best solution is proven
    optimal (status ``"optimal"``). With an unlimited budget the search is *eventually optimal*.

Cost
    The sum of costs: every agent pays one per time step until its final arrival. A
    configuration alone does not say whether an agent at its goal will leave it again, so the
    search state also holds the agents that have *finished* (they stay at their goals for good;
    an agent at a goal no edge leaves finishes on arrival): the cost of a step is the number of
    agents not finished. Before a first solution nobody finishes otherwise; after it, an agent
    at its goal finishes there unless a low-level constraint moves it or keeps it unfinished,
    and "stays for good" is one more low-level option. Every solution found is also re-inserted
    with its agents finished at their final arrivals, so that its cost-to-come is its sum of
    costs. The heuristic is the sum of the unfinished agents' distances to their goals
    (admissible).

Successor generators
    ``"unit"`` time without proximity: the MovingAI semantics (vertex and swap conflicts; an
    agent may follow another into the node it leaves, and agents may rotate along a cycle), with
    the one-step PIBT and two rules for corridors: two agents that must pass each other where
    pushing leads into a dead end swap by the one stepping back and the other following it, and a
    pushed agent does not run ahead of its pusher into a corridor the pusher will stop in (at its
    goal) and it must come back through. ``"durative"`` time, or proximity: occupancy as
    :func:`~agents.search.mapf.validate.validate` checks it, as in the stepper of
    :mod:`agents.search.mapf.pibt`: an agent moving along ``u -> v`` (``d`` steps) occupies both
    ends for all ``d`` steps, and no node an agent occupies may be at or near a node another
    occupies. A configuration then holds, per agent, its node, or the edge it is on and the steps
    left (an agent in flight has a single successor). PIBT there is conservative (an agent only
    enters a node nobody occupies or is near; a pushed agent starts to move away while its pusher
    waits; an agent arrives for good at a goal no edge leaves only where every other agent can
    still reach its goal), but a constraint set that fixes every agent's move is checked exactly
    (under unit time with proximity: positions at every time, and swaps), so completeness holds
    under either model. A configuration in which an agent can no longer reach its goal around the
    agents staying for good is not searched below.

What it does not do
    It does not bound the cost of the first solution (a multiple of the lower bound on crowded
    maps); refining it converges slowly with more than a few dozen agents; the proof of
    optimality or infeasibility needs the whole configuration space below the best cost, in
    reach with a handful of agents on a small graph only. The budget is counted in work
    (``expansion_limit``), and reaching it ends the search with the best solution so far
    (``"suboptimal"``) or none (``"timeout"``). Ties are broken by a generator seeded by
    ``seed``; the same instance, options and seed give the same result on any machine.
"""
from __future__ import annotations

import heapq
import random
import sys
from collections import deque
from dataclasses import dataclass
from typing import Deque, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from scipy.sparse.csgraph import breadth_first_order, connected_components, dijkstra

from .instance import UNREACHABLE, MapfInstance
from .pibt import _overlap
from .prioritized import SolveRun, check_common_options, no_plan_reason, plan_result
from .result import MapfResult
from .sipp import BudgetExceeded, Events

__all__ = ["ConfigurationStats", "DEFAULT_LACAM_EXPANSION_LIMIT", "solve_lacam"]

#: default ``expansion_limit``: the work of one solve, counted as agents placed and candidate moves
#: examined by the successor generator, low-level constraints made and edges relaxed by the repair
#: of costs-to-come (5 to 10 s on one core with 300 to 400 agents on a 32 x 32 grid)
DEFAULT_LACAM_EXPANSION_LIMIT = 20_000_000
#: low-level option "stay at the goal for good" (the agent finishes)
FINISH = -1


@dataclass
class ConfigurationStats:
    """Statistics of one configuration search (its work and seconds are the result's)."""

    #: high-level nodes (joint configurations) made
    configurations: int = 0
    #: successor generations, one per low-level constraint set taken up
    generations: int = 0
    #: calls of the successor generator
    generator_calls: int = 0


def _constraints(c: tuple) -> List[Tuple[int, int]]:
    """The ``(agent, option)`` pairs of a low-level node ``(parent, agent, option, depth)`` (the
    root is ``(None, -1, 0, 0)``), root first."""
    out: List[Tuple[int, int]] = []
    while c[0] is not None:
        out.append((c[1], c[2]))
        c = c[0]
    out.reverse()
    return out


class _Node:
    """A high-level node: a configuration, the finished agents, its search bookkeeping."""

    __slots__ = ("pos", "tgt", "rem", "fin", "parent", "g", "h", "prio", "order", "tree", "nbrs", "deferred",
                 "goal", "fixed", "soft", "serial")

    def __init__(self, pos: Tuple[int, ...], tgt: Optional[Tuple[int, ...]], rem: Optional[Tuple[int, ...]],
                 fin: Tuple[int, ...], parent: Optional["_Node"], g: int) -> None:
        self.pos = pos
        self.tgt = tgt
        self.rem = rem
        self.fin = fin
        self.parent = parent
        self.g = g
        self.h = 0
        self.prio: List[float] = []
        self.order: List[int] = []
        self.tree: Deque[tuple] = deque()
        self.nbrs: List["_Node"] = []
        self.deferred: List[tuple] = []
        self.goal = False
        #: agents that stay for good (finished, or at a goal no edge leaves)
        self.fixed: Tuple[int, ...] = ()
        #: agents at their goals that finish unless a constraint moves them (once a solution exists)
        self.soft: Tuple[int, ...] = ()
        self.serial = 0  # creation order: ties between equal costs-to-come


# ---------------------------------------------------------------------------------------------
# successor generators
# ---------------------------------------------------------------------------------------------
#: at most this many orderings of one agent's candidates are kept (ties broken at random)
_ORDERINGS = 6
#: before a first solution, successor generations without a configuration closer to the goals
#: (sum of distances) after which the search dives again from the starts
_PATIENCE = 1000


def _orderings(succ: Sequence[int], h: Sequence[int], rng: random.Random) -> Tuple[List[int], ...]:
    """Orderings of the nodes of ``succ`` from which the goal can be reached, by distance ``h``,
    that differ only in the order of equally distant ones (all of them, or ``_ORDERINGS`` drawn)."""
    nodes = [v for v in succ if h[v] < UNREACHABLE]
    nodes.sort(key=lambda v: h[v])
    groups: List[List[int]] = []
    for v in nodes:
        if groups and h[groups[-1][0]] == h[v]:
            groups[-1].append(v)
        else:
            groups.append([v])
    if all(len(g) == 1 for g in groups):
        return (nodes,)
    out: List[List[int]] = []
    seen = set()
    for _ in range(4 * _ORDERINGS):
        order: List[int] = []
        for g in groups:
            g = list(g)
            rng.shuffle(g)
            order.extend(g)
        key = tuple(order)
        if key not in seen:
            seen.add(key)
            out.append(order)
            if len(out) == _ORDERINGS:
                break
    return tuple(out)


class _UnitGen:
    """PIBT under unit time without proximity: vertex and swap conflicts, following and rotations
    allowed (the MovingAI semantics)."""

    def __init__(self, inst: MapfInstance, rng: random.Random, counter: List[int]) -> None:
        n = inst.n_nodes
        self.n = n
        self.succ = inst.succ
        self.h = inst.h
        self.goals = inst.goals
        self.rng = rng
        #: per ``agent * n + node``, orderings of the successors from which the agent's goal can be
        #: reached, best first, that differ only between equally good ones (a call picks one)
        self.cache: Dict[int, Tuple[List[int], ...]] = {}
        self.occ_now = [-1] * n
        self.occ_next = [-1] * n
        self.counter = counter
        self.calls = 0
        self.degree = [len(inst.succ[v]) - 1 for v in range(n)]

    def candidates(self, a: int, u: int) -> Tuple[List[int], ...]:
        key = a * self.n + u
        c = self.cache.get(key)
        if c is None:
            c = self.cache[key] = _orderings(self.succ[u], self.h[a], self.rng)
        return c

    def options(self, node: _Node, a: int, nxt: List[int]) -> List[int]:
        """``a``'s moves compatible with the agents whose next node is already set in ``nxt``."""
        occ_now, occ_next = self.occ_now, self.occ_next
        u = node.pos[a]
        out = []
        for v in self.candidates(a, u)[0]:
            if occ_next[v] >= 0:
                continue
            j = occ_now[v]
            if j >= 0 and j != a and nxt[j] == u:
                continue
            out.append(v)
        return out

    def generate(self, node: _Node, cons: Sequence[Tuple[int, int]], who: int
                 ) -> Tuple[Optional[Tuple[tuple, None, None]], List[int]]:
        """The successor of ``node`` under the constraints ``cons`` (``None`` if there is none) and
        the options of agent ``who`` (``-1``: none) compatible with them."""
        self.calls += 1
        pos = node.pos
        k = len(pos)
        self.counter[0] += k
        occ_now, occ_next = self.occ_now, self.occ_next
        nxt = [-1] * k
        for i in range(k):
            occ_now[pos[i]] = i
        try:
            for i in node.fixed:
                u = pos[i]
                nxt[i] = u
                occ_next[u] = i
            for a, v in cons:
                u = pos[a]
                if v == FINISH:
                    v = u
                if occ_next[v] >= 0:
                    return None, []
                j = occ_now[v]
                if j >= 0 and j != a and nxt[j] == u:
                    return None, []
                nxt[a] = v
                occ_next[v] = a
            opts = self.options(node, who, nxt) if who >= 0 else []
            for a in node.soft:  # finish where they are unless constrained
                if nxt[a] < 0:
                    u = pos[a]
                    if occ_next[u] >= 0:
                        return None, opts
                    nxt[a] = u
                    occ_next[u] = a
            if self._pibt_all(node, nxt):
                return (tuple(nxt), None, None), opts
            return None, opts
        finally:
            # every node reserved is some agent's next node (a reservation taken over is overwritten)
            for u in pos:
                occ_now[u] = -1
            for v in nxt:
                if v >= 0:
                    occ_next[v] = -1

    def _pibt_all(self, node: _Node, nxt: List[int]) -> bool:
        pos = node.pos
        occ_now, occ_next = self.occ_now, self.occ_next
        cache = self.cache
        n = self.n
        make = self.candidates
        h, goals = self.h, self.goals
        salt = self.rng.getrandbits(30) | 1
        swap_needed = self._swap_needed
        blocked_ahead = self._blocked_ahead
        work = 0

        def pibt(i: int, pusher: int) -> bool:
            nonlocal work
            u = pos[i]
            orders = cache.get(i * n + u) or make(i, u)
            cands = orders[((salt * (2 * i + 1)) >> 7) % len(orders)] if len(orders) > 1 else orders[0]
            if pusher >= 0 and len(cands) > 2:
                hp = h[pusher]
                ahead = [w for w in cands if w != u and hp[w] < hp[u] and blocked_ahead(pusher, i, u, w, True)]
                if ahead:  # the pusher would push it on into a corridor it must come back from
                    cands = [w for w in cands if w not in ahead] + ahead
            follower = -1
            best = cands[0]
            if best != u:
                j = occ_now[best]
                if j >= 0 and nxt[j] < 0 and swap_needed(i, j, u, best, pos):
                    cands = cands[::-1]  # step back and let j follow: a swap in a corridor
                    follower = j
            for v in cands:
                work += 1
                if occ_next[v] >= 0:
                    continue
                j = occ_now[v]
                if j >= 0 and j != i and nxt[j] == u:
                    continue  # j comes to u: a swap
                occ_next[v] = i
                nxt[i] = v
                if not (j < 0 or j == i or nxt[j] >= 0 or pibt(j, i)):
                    nxt[i] = -1  # j stays at v
                    continue
                if follower >= 0 and v != best and nxt[follower] < 0 and occ_next[u] < 0:
                    nxt[follower] = u
                    occ_next[u] = follower
                return True
            w = occ_next[u]
            if w >= 0 and w != pusher:
                return False  # a constrained agent comes here and this one cannot leave
            occ_next[u] = i
            nxt[i] = u
            return False

        try:
            for a in node.order:
                if nxt[a] >= 0:
                    continue
                u = pos[a]
                if u == goals[a] and occ_next[u] < 0:  # at its goal, nobody wants it away: stays
                    work += 1
                    occ_next[u] = a
                    nxt[a] = u
                    continue
                if not pibt(a, -1) and nxt[a] < 0:
                    return False
            return True
        finally:
            self.counter[0] += work

    # ---------------------------------------------------------------- swaps in corridors
    def _swap_needed(self, i: int, j: int, u: int, v: int, pos: Sequence[int]) -> bool:
        """Whether ``i`` at ``u`` and ``j`` at ``v`` (where ``i`` wants to go) must pass each other
        in a corridor (:meth:`_blocked_ahead`) and can: ``i`` stepping back (``j`` following)
        reaches a place where the two can pass."""
        if not self._blocked_ahead(i, j, u, v):
            return False
        prev, cur = v, u
        for _ in range(self.n):
            nxt = self._way_on(cur, prev)
            if nxt is None:
                return True
            if nxt < 0 or nxt == v:
                return False
            prev, cur = cur, nxt
        return False

    def _blocked_ahead(self, i: int, j: int, u: int, v: int, parks: bool = False) -> bool:
        """Whether ``j`` at ``v``, pushed on ahead of ``i`` (at ``u``), reaches no place where it
        could step aside before ``i`` stops getting closer to its goal (``parks``: ``i`` reaches
        its goal there), and then wants to get back past ``i``."""
        hi, hj = self.h[i], self.h[j]
        prev, cur = u, v
        for _ in range(self.n):
            if hi[cur] >= hi[prev]:
                break
            nxt = self._way_on(cur, prev)
            if nxt is None:
                return False  # a place to step aside
            if nxt < 0:
                break  # a dead end
            prev, cur = cur, nxt
        else:
            return False
        if not (hj[prev] < hj[cur] and (hi[prev] == 0 if parks else (hi[prev] == 0 or hi[cur] < hi[prev]))):
            return False
        for x in self.succ[cur][1:]:
            if x != prev and hj[x] < hj[cur]:
                return False  # j has another way as short
        return True

    def _way_on(self, cur: int, prev: int) -> Optional[int]:
        """The one node to go on to from ``cur`` coming from ``prev`` (``-1``: none, a dead end;
        ``None``: several, a place where two agents can pass)."""
        way = -1
        for w in self.succ[cur][1:]:
            if w == prev or self._parked(w):
                continue
            if way >= 0:
                return None
            way = w
        return way

    def _parked(self, w: int) -> bool:
        """An agent at its goal at the end of a dead end: it will not make room."""
        a = self.occ_now[w]
        return a >= 0 and self.degree[w] == 1 and self.h[a][w] == 0


#: at most this many sets of agents staying for good keep their distances cached
_VIEWS = 64


class _View:
    """What one set of agents staying for good closes (see :meth:`_OccGen.view`)."""

    __slots__ = ("closed", "dist", "cands", "parts")

    def __init__(self, closed: Optional[np.ndarray]) -> None:
        self.closed = closed
        self.dist: Dict[int, List[int]] = {}
        self.cands: Dict[int, List[Tuple[int, int, int]]] = {}
        self.parts: Dict[int, tuple] = {}


class _OccGen:
    """PIBT over occupancy (durative edges, proximity): an agent occupies its node, or both ends
    of the edge it is on, and no node an agent occupies may be at or near one another occupies.

    Unconstrained agents only start moves to nodes nobody occupies or is near (every agent may
    always wait); constrained agents are checked exactly, under the durative occupancy or, with
    unit time, the unit semantics (positions at every time and swaps)."""

    def __init__(self, inst: MapfInstance, rng: random.Random, counter: List[int]) -> None:
        n = inst.n_nodes
        self.n = n
        self.inst = inst
        self.unit = inst.unit
        near = inst.near
        self.zone: List[List[int]] = [[x] + near[x] for x in range(n)] if near is not None else [[x] for x in range(n)]
        self.near_set: List[frozenset] = ([frozenset(near[x]) for x in range(n)] if near is not None
                                          else [frozenset()] * n)
        self.succ_d = inst.succ_d
        self.goals = inst.goals
        #: agents whose goal no edge leaves: once there, they stay for good
        self.final = [len(inst.succ[g]) == 1 for g in inst.goals]
        self.edges = inst.durations.tocsr()
        self.reverse = self.edges.T.tocsr()
        self.reverse_rows = np.repeat(np.arange(n), np.diff(self.reverse.indptr))
        self.tie = [rng.random() for _ in range(n)]
        self.views: Dict[Tuple[int, ...], _View] = {}
        self.count = [0] * n  # occupied nodes at or near each node, this step
        self.holder = [-1] * n  # the agent occupying each node
        self.mark = [0] * n  # unit time: next positions of constrained agents at or near each node
        self.claim_owner = [-1] * n
        self.claim_stamp = [0] * n
        self.stamp = 0
        self.counter = counter
        self.calls = 0

    # ---------------------------------------------------------------- agents staying for good
    def view(self, node: _Node) -> "_View":
        """What the agents staying for good (``node.fixed``) close: the nodes at and near them,
        the other agents' distances around those, their candidates."""
        v = self.views.get(node.fixed)
        if v is None:
            if len(self.views) >= _VIEWS:
                self.views.clear()
            closed = np.zeros(self.n, dtype=bool)
            for a in node.fixed:
                closed[self.zone[node.pos[a]]] = True
            v = self.views[node.fixed] = _View(closed if node.fixed else None)
            if node.fixed:  # the others' distances around the closed nodes, in one call
                fixed = set(node.fixed)
                others = [a for a in range(len(self.goals)) if a not in fixed]
                keep = ~closed
                m = self.reverse.copy()
                m.data[~(keep[self.reverse_rows] & keep[m.indices])] = 0
                m.eliminate_zeros()  # (an explicit zero would be an edge of length 0)
                if others:
                    # counted as work: about one unit per 16 nodes settled (a unit: one candidate move)
                    self.counter[0] += len(others) * self.n // 16
                    dist = np.atleast_2d(dijkstra(m, directed=True, indices=[self.goals[a] for a in others],
                                                  unweighted=self.unit))
                    rows = np.where(np.isfinite(dist), dist, UNREACHABLE).astype(np.int64).tolist()
                    v.dist.update(zip(others, rows))
        return v

    def distances(self, view: "_View", a: int) -> List[int]:
        """``a``'s steps to its goal around the closed nodes of ``view`` (an agent staying for good:
        its distances without them)."""
        d = view.dist.get(a)
        return self.inst.h[a] if d is None else d

    def candidates(self, view: "_View", a: int, u: int) -> List[Tuple[int, int, int]]:
        """``(rank key, node, duration)``: waiting, and the moves from which ``a``'s goal can be
        reached around the closed nodes, best first by the steps to the goal through them."""
        key = a * self.n + u
        c = view.cands.get(key)
        if c is None:
            h, tie, unit = self.distances(view, a), self.tie, self.unit
            closed = view.closed
            opts = [(h[u] + 1, u, 1)]
            for v, d in self.succ_d[u][1:]:
                if h[v] < UNREACHABLE and (closed is None or not closed[v]):
                    d = 1 if unit else d
                    opts.append((d + h[v], v, d))
            opts.sort(key=lambda o: (o[0], o[1] != u, tie[o[1]]))
            c = view.cands[key] = opts
        return c

    def may_park(self, view: "_View", node: _Node, a: int) -> bool:
        """Whether ``a`` may arrive at its goal, which no edge leaves, for good: every other agent
        not staying for good can still reach its goal with the nodes at and near it closed."""
        return self._all_reach(view, node, a)

    def stuck(self, node: _Node) -> bool:
        """Whether some agent can no longer reach its goal around the agents staying for good
        (then no plan goes through ``node``)."""
        return not self._all_reach(self.view(node), node, -1)

    def _all_reach(self, view: "_View", node: _Node, a: int) -> bool:
        """Whether every agent not staying for good (but ``a``) can reach its goal around the
        closed nodes of ``view`` and, if ``a >= 0``, the nodes at and near ``a``'s goal."""
        parts = view.parts.get(a)
        if parts is None:
            self.counter[0] += self.n
            keep = np.ones(self.n, dtype=bool) if view.closed is None else ~view.closed
            if a >= 0:
                keep[self.zone[self.goals[a]]] = False
            idx = np.flatnonzero(keep)
            inv = np.full(self.n, -1, dtype=np.int64)
            inv[idx] = np.arange(len(idx))
            sub = self.edges[idx][:, idx].tocsr()
            if len(idx):
                _, labels = connected_components(sub, directed=True, connection="strong")
                big = labels == np.bincount(labels).argmax()
            else:
                big = np.zeros(0, dtype=bool)
            bigf = big.astype(np.float64)
            into = (sub @ bigf > 0) | big  # in the largest strongly connected part or with an edge into it
            out = (sub.T.tocsr() @ bigf > 0) | big  # in it or with an edge from it
            parts = view.parts[a] = (inv, sub, into, out)
        inv, sub, into, out = parts
        pos, tgt = node.pos, node.tgt
        assert tgt is not None
        fixed = set(node.fixed)
        for b in range(len(pos)):
            if b == a or b in fixed:
                continue
            s_b, d_b = int(inv[tgt[b] if tgt[b] >= 0 else pos[b]]), int(inv[self.goals[b]])
            if s_b < 0 or d_b < 0:
                return False
            if into[s_b] and out[d_b]:
                continue
            seen = breadth_first_order(sub, s_b, directed=True, return_predecessors=False)
            if not (seen == d_b).any():
                return False
        return True

    def generate(self, node: _Node, cons: Sequence[Tuple[int, int]], who: int
                 ) -> Tuple[Optional[Tuple[tuple, tuple, tuple]], List[int]]:
        """As :meth:`_UnitGen.generate`; an option is a node (wait: the agent's own) or ``FINISH``."""
        self.calls += 1
        pos, tgt, rem = node.pos, node.tgt, node.rem
        assert tgt is not None and rem is not None
        k = len(pos)
        zone, count, holder, mark = self.zone, self.count, self.holder, self.mark
        unit = self.unit
        occupied: List[int] = []
        for a in range(k):
            for x in (pos[a], tgt[a]):
                if x >= 0:
                    holder[x] = a
                    occupied.append(x)
                    for y in zone[x]:
                        count[y] += 1
        move = [-1] * k  # the node a move started now goes to
        decided = [False] * k
        marked: List[int] = []
        forced: List[int] = []
        self.stamp += 1
        self.counter[0] += k
        view = self.view(node)
        try:
            for a in range(k):
                if tgt[a] >= 0:
                    decided[a] = True
            for a in node.fixed:
                decided[a] = True
                if unit:
                    self._mark(pos[a], marked)
            if unit:
                ok = self._unit_constraints(node, cons, move, decided, marked, occupied)
            else:
                ok = self._durative_constraints(node, cons, move, decided, occupied)
            if not ok:
                return None, []
            opts = self._options(view, node, who, move) if who >= 0 else []
            for a in node.soft:  # finish where they are unless constrained
                if not decided[a]:
                    decided[a] = True
                    if unit and not self._mark(pos[a], marked):
                        return None, opts
            if unit:  # agents a constrained agent comes at or near must leave
                for a in node.order:
                    if not decided[a] and mark[pos[a]]:
                        forced.append(a)
            if self._pibt_all(view, node, move, decided, forced, occupied):
                return self._child(node, move), opts
            return None, opts
        finally:
            for x in occupied:
                holder[x] = -1
                for y in zone[x]:
                    count[y] = 0
            for x in marked:
                for y in zone[x]:
                    mark[y] = 0

    # ---------------------------------------------------------------- constraints
    def _mark(self, x: int, marked: List[int]) -> bool:
        """Unit time: set ``x`` as a next position; ``False`` if it is at or near another."""
        mark = self.mark
        if mark[x]:
            return False
        marked.append(x)
        for y in self.zone[x]:
            mark[y] += 1
        return True

    def _unit_constraints(self, node: _Node, cons: Sequence[Tuple[int, int]], move: List[int],
                          decided: List[bool], marked: List[int], occupied: List[int]) -> bool:
        pos = node.pos
        goes: Dict[int, int] = {}
        for a, v in cons:
            u = pos[a]
            if v == FINISH:
                v = u
            if not self._mark(v, marked):
                return False
            if v != u:
                back = goes.get(v)
                if back is not None and back == u:
                    return False  # a swap
                goes[u] = v
                move[a] = v
                self._occupy(v, occupied)
            decided[a] = True
        return True

    def _durative_constraints(self, node: _Node, cons: Sequence[Tuple[int, int]], move: List[int],
                              decided: List[bool], occupied: List[int]) -> bool:
        pos = node.pos
        for a, v in cons:
            u = pos[a]
            decided[a] = True
            if v == FINISH or v == u:
                continue
            if not self._is_open(u, v):
                return False
            move[a] = v
            self._occupy(v, occupied)
        return True

    def _options(self, view: "_View", node: _Node, a: int, move: List[int]) -> List[int]:
        """``a``'s moves compatible with the constrained agents' (from which its goal can still be
        reached)."""
        u = node.pos[a]
        out = []
        if self.unit:
            mark = self.mark
            holder = self.holder
            for _, v, _d in self.candidates(view, a, u):
                if mark[v]:
                    continue
                if v != u:
                    b = holder[v]
                    if b >= 0 and move[b] == u:
                        continue
                out.append(v)
            return out
        for _, v, _d in self.candidates(view, a, u):
            if v == u or self._is_open(u, v):
                out.append(v)
        return out

    # ---------------------------------------------------------------- occupation
    def _occupy(self, v: int, occupied: List[int]) -> None:
        """A move to ``v`` starts: the nodes at and near ``v`` are occupied for this step."""
        count = self.count
        for y in self.zone[v]:
            count[y] += 1
        occupied.append(v)

    def _is_open(self, u: int, v: int) -> bool:
        """No node at or near ``v`` is occupied, except ``u`` by the agent itself."""
        own = 1 if v in self.near_set[u] else 0
        return self.count[v] == own

    def _claimed_by_other(self, x: int, a: int) -> bool:
        return self.claim_stamp[x] == self.stamp and self.claim_owner[x] != a

    # ---------------------------------------------------------------- PIBT
    def _pibt_all(self, view: "_View", node: _Node, move: List[int], decided: List[bool], forced: List[int],
                  occupied: List[int]) -> bool:
        pos = node.pos
        holder = self.holder
        zone = self.zone
        claim_stamp, claim_owner = self.claim_stamp, self.claim_owner
        stamp = self.stamp
        tgt = node.tgt
        assert tgt is not None
        goals, final = self.goals, self.final
        work = 0
        failed = [False] * len(pos)

        def cands_of(a: int, u: int) -> List[Tuple[int, int, int]]:
            return self.candidates(view, a, u)

        def can_enter(a: int, u: int, v: int) -> bool:
            if self._claimed_by_other(v, a) or not self._is_open(u, v):
                return False
            return not (v == goals[a] and final[a] and not self.may_park(view, node, a))

        def start(a: int, v: int) -> None:
            move[a] = v
            self._occupy(v, occupied)

        def push(a: int, v: int) -> bool:
            blockers: List[int] = []
            leaving = False
            for y in zone[v]:
                b = holder[y]
                if b < 0 or b == a or b in blockers:
                    continue
                if tgt[b] >= 0 or move[b] >= 0:
                    leaving = True  # on its way: it leaves (or is pushed once it arrives)
                    continue
                if decided[b]:
                    return False  # it has decided to stay this step
                blockers.append(b)
            if not blockers and not leaving:
                return False  # nobody in the way to push: others come here
            mine = []
            for y in zone[v]:
                if claim_stamp[y] != stamp:
                    claim_stamp[y] = stamp
                    claim_owner[y] = a
                    mine.append(y)
            for b in blockers:
                ok = (not failed[b]) if decided[b] else pibt(b, True)
                if not ok:
                    for y in mine:
                        claim_stamp[y] = 0
                    return False
            return True

        def pibt(a: int, pushed: bool) -> bool:
            nonlocal work
            decided[a] = True
            u = pos[a]
            cands = cands_of(a, u)
            if pushed:
                for _, v, _d in cands:
                    work += 1
                    if v != u and can_enter(a, u, v):
                        start(a, v)
                        return True
            i, m = 0, len(cands)
            while i < m:
                j = i + 1
                while j < m and cands[j][0] == cands[i][0]:
                    j += 1
                group = cands[i:j]
                i = j
                for _, v, _d in group:
                    work += 1
                    if v == u:
                        if not pushed:
                            return True  # waiting first among equals
                    elif not pushed and can_enter(a, u, v):
                        start(a, v)
                        return True
                for _, v, _d in group:
                    work += 1
                    if v != u and not self._claimed_by_other(v, a) and not self._is_open(u, v) and push(a, v):
                        return True  # waits while the agents in the way leave
            failed[a] = True
            return not pushed

        try:
            for a in forced:  # must leave now: an open node, or the constraints fail
                decided[a] = True
                u = pos[a]
                for _, v, _d in cands_of(a, u):
                    work += 1
                    if v != u and can_enter(a, u, v):
                        start(a, v)
                        break
                else:
                    return False
            for a in node.order:
                if not decided[a]:
                    pibt(a, False)
            return True
        finally:
            self.counter[0] += work

    def _child(self, node: _Node, move: List[int]) -> Tuple[tuple, tuple, tuple]:
        pos, tgt, rem = node.pos, node.tgt, node.rem
        assert tgt is not None and rem is not None
        npos, ntgt, nrem = list(pos), list(tgt), list(rem)
        unit = self.unit
        for a in range(len(pos)):
            if tgt[a] >= 0:
                r = rem[a] - 1
                if r == 0:
                    npos[a], ntgt[a], nrem[a] = tgt[a], -1, 0
                else:
                    nrem[a] = r
            elif move[a] >= 0:
                v = move[a]
                d = 1 if unit else self._duration(pos[a], v)
                if d == 1:
                    npos[a] = v
                else:
                    ntgt[a], nrem[a] = v, d - 1
        return tuple(npos), tuple(ntgt), tuple(nrem)

    def _duration(self, u: int, v: int) -> int:
        for w, d in self.succ_d[u]:
            if w == v:
                return d
        raise AssertionError(f"no edge {u}->{v}")


# ---------------------------------------------------------------------------------------------
# the high-level search
# ---------------------------------------------------------------------------------------------
class _Search:
    """One LaCAM* search: the explored configurations, the open stack, the best solution."""

    def __init__(self, inst: MapfInstance, gen: Union["_UnitGen", "_OccGen"], rng: random.Random, run: SolveRun,
                 anytime: bool) -> None:
        self.inst = inst
        self.gen = gen
        self.rng = rng
        self.run = run
        self.anytime = anytime
        self.k = inst.n_agents
        self.goals = inst.goals
        self.h = inst.h
        #: agents whose goal no edge leaves: they finish on arrival
        self.final = [len(inst.succ[g]) == 1 for g in inst.goals]
        self.explored: Dict[tuple, _Node] = {}
        #: the open nodes: a stack (the last one is taken up next)
        self.open: Deque[_Node] = deque()
        #: the best plan so far (its configurations) and its sum of costs, which bounds the search
        self.plan: Optional[List[_Node]] = None
        self.bound = UNREACHABLE
        self.improved = False  # a better plan since the search loop last looked
        self.finishing = False  # "finish" options offered (once a solution exists)
        self.generated = 0
        self.expanded = 0

    # ---------------------------------------------------------------- nodes
    def setup(self, node: _Node, parent: Optional[_Node]) -> None:
        """Heuristic, priorities, agent order, goal test and the constraint tree's root."""
        pos, tgt, rem, goals, h = node.pos, node.tgt, node.rem, self.goals, self.h
        k = self.k
        fin = set(node.fin)
        at_goal = [pos[a] == goals[a] and (tgt is None or tgt[a] < 0) for a in range(k)]
        fixed = sorted(fin | {a for a in range(k) if at_goal[a] and self.final[a]})
        node.fixed = tuple(fixed)
        fixed_set = set(fixed)
        if self.finishing:  # agents at their goals finish there unless a constraint moves them
            node.soft = tuple(a for a in range(k) if at_goal[a] and a not in fixed_set)
        self.run.counter[0] += k
        est = 0
        for a in range(k):
            if a in fin:
                continue
            if tgt is not None and rem is not None and tgt[a] >= 0:
                est += rem[a] + h[a][tgt[a]]
            else:
                est += h[a][pos[a]]
        node.h = est
        node.goal = all(at_goal)
        if parent is None:
            top = max(1, max((h[a][pos[a]] for a in range(k)), default=1) + 1)
            prio = [h[a][pos[a]] / top for a in range(k)]
        else:
            prio = list(parent.prio)
            for a in range(k):
                if at_goal[a]:
                    prio[a] -= int(prio[a])
                else:
                    prio[a] += 1.0
        node.prio = prio
        movable = [a for a in range(k) if a not in fixed_set and (tgt is None or tgt[a] < 0)]
        movable.sort(key=lambda a: -prio[a])
        node.order = movable
        stuck = getattr(self.gen, "stuck", None)
        if (stuck is not None and parent is not None and node.fixed != parent.fixed and not node.goal
                and stuck(node)):
            return  # an agent can no longer reach its goal: nothing to search below
        node.tree.append((None, -1, 0, 0))

    def cost(self, child: _Node) -> int:
        """The cost of a step into ``child``: the agents not finished (finishing is decided when the
        step is taken, so an agent that finishes at the step's start does not pay for it)."""
        return self.k - len(child.fin)

    def add(self, parent: Optional[_Node], state: tuple, fin: Tuple[int, ...]) -> _Node:
        """The node of ``state`` reached from ``parent``: a new one, or the known one with its
        costs-to-come repaired through the new edge (LaCAM*'s rewiring)."""
        pos, tgt, rem = state
        key = (pos, tgt, rem, fin)
        node = self.explored.get(key)
        if node is None:
            node = _Node(pos, tgt, rem, fin, parent, 0)
            node.serial = self.generated
            if parent is not None:
                node.g = parent.g + self.cost(node)
                parent.nbrs.append(node)
            self.setup(node, parent)
            self.explored[key] = node
            self.generated += 1
            if node.goal:
                self.found(node)
            self.open.append(node)
            return node
        assert parent is not None
        if node not in parent.nbrs:
            parent.nbrs.append(node)
        self.rewire(parent)
        if node.g + node.h < self.bound:
            self.open.append(node)  # taken up again
        return node

    def rewire(self, start: _Node) -> None:
        """Propagate lower costs-to-come from ``start`` over the edges found so far."""
        heap = [(start.g, start.serial, start)]
        k = self.k
        counter = self.run.counter
        while heap:
            g, _, a = heapq.heappop(heap)
            if g != a.g:
                continue
            counter[0] += len(a.nbrs)
            for b in a.nbrs:
                ng = g + k - len(b.fin)
                if ng < b.g:
                    b.g = ng
                    b.parent = a
                    heapq.heappush(heap, (ng, b.serial, b))
                    if b.goal:
                        self.found(b)
                    elif ng + b.h < self.bound:
                        self.open.append(b)

    def found(self, node: _Node) -> None:
        """A goal configuration reached (or reached cheaper): keep its plan if it is the best."""
        nodes = self.path(node)
        soc = sum(self.arrivals(nodes))
        if soc >= self.bound:
            return
        self.plan, self.bound, self.improved = nodes, soc, True
        if not self.finishing and self.anytime:
            self.finishing = True
            for other in list(self.explored.values()):
                if other.deferred:
                    other.tree.extend(other.deferred)
                    other.deferred = []
                    self.open.append(other)

    def arrivals(self, nodes: Sequence[_Node]) -> List[int]:
        """Each agent's final arrival along ``nodes``: after the last time it is not at rest at its goal."""
        k, goals = self.k, self.goals
        last = [0] * k
        for t, node in enumerate(nodes):
            tgt = node.tgt
            for a in range(k):
                if node.pos[a] != goals[a] or (tgt is not None and tgt[a] >= 0):
                    last[a] = t + 1
        return last

    def path(self, goal: _Node) -> List[_Node]:
        out = []
        node: Optional[_Node] = goal
        while node is not None:
            out.append(node)
            node = node.parent
        out.reverse()
        return out

    def finish_on_arrival(self, nodes: List[_Node]) -> None:
        """Re-insert the plan ``nodes`` with every agent finished at its final arrival, so that its
        cost-to-come is its sum of costs (each new node reached from the previous one)."""
        k = self.k
        last = self.arrivals(nodes)
        prev = nodes[0]
        for t in range(1, len(nodes)):
            node = nodes[t]
            fin = tuple(a for a in range(k) if last[a] <= t - 1)
            if fin == node.fin:
                prev = node
                continue
            prev = self.add(prev, (node.pos, node.tgt, node.rem), fin)

    # ---------------------------------------------------------------- the loop
    def search(self) -> bool:
        """Run until the budget ends (``BudgetExceeded`` / ``TimeoutError``), the open stack empties
        (``True``: exhausted) or, without ``anytime``, a first solution is found (``False``)."""
        run, gen, rng = self.run, self.gen, self.rng
        open_ = self.open
        counter = run.counter
        root = open_[0] if open_ else None
        lowest, since = (root.h, 0) if root is not None else (0, 0)
        while open_:
            run.check_limits()
            if self.plan is None and root is not None:
                if self.expanded - since > _PATIENCE:  # no step closer to the goals for long: dive again
                    open_.append(root)
                    since = self.expanded
            node = open_[-1]
            if node.h < lowest:
                lowest, since = node.h, self.expanded
            improving = self.plan is not None
            if improving:
                if not self.anytime:
                    return False
                if node.g + node.h >= self.bound:
                    open_.pop()
                    continue
            if node.goal or not node.tree:
                open_.pop()
                continue
            c = node.tree.popleft()
            depth = c[3]
            who = node.order[depth] if depth < len(node.order) else -1
            cons = _constraints(c)
            state, opts = gen.generate(node, cons, who)
            self.expanded += 1
            if who >= 0 and opts:
                pos = node.pos
                finish = pos[who] == self.goals[who] and pos[who] in opts
                rng.shuffle(opts)
                for v in opts:
                    node.tree.append((c, who, v, depth + 1))
                if finish:
                    item = (c, who, FINISH, depth + 1)
                    if self.finishing:
                        node.tree.append(item)
                    else:
                        node.deferred.append(item)
                counter[0] += len(opts)
            if state is None:
                if improving and open_[-1] is node:
                    open_.pop()
                    open_.appendleft(node)
                continue
            fin = node.fixed
            if node.soft or any(v == FINISH for _, v in cons):
                told = {a: v for a, v in cons}
                done = set(fin) | {a for a, v in told.items() if v == FINISH}
                done.update(a for a in node.soft if a not in told)
                fin = tuple(sorted(done))
            self.add(node, state, fin)
            if self.improved:
                self.improved = False
                if not self.anytime:
                    return False
                assert self.plan is not None
                self.finish_on_arrival(self.plan)
                self.improved = False  # (re-inserted: the same sum of costs)
            elif improving and open_ and open_[-1] is node:
                # improving: nothing new to follow from here; the other open nodes take their turn
                open_.pop()
                open_.appendleft(node)
        return True

    # ---------------------------------------------------------------- the plan
    def paths(self, nodes: List[_Node]) -> List[Events]:
        """Each agent's events along ``nodes``: its node at every time it is at rest, up to its
        final arrival."""
        k = self.k
        events: List[Events] = [[] for _ in range(k)]
        for t, node in enumerate(nodes):
            tgt = node.tgt
            for a in range(k):
                if tgt is None or tgt[a] < 0:
                    events[a].append((node.pos[a], t))
        out = []
        for ev in events:
            while len(ev) >= 2 and ev[-1][0] == ev[-2][0]:
                ev.pop()
            out.append(ev)
        return out


def solve_lacam(inst: MapfInstance, *, expansion_limit: Optional[int] = DEFAULT_LACAM_EXPANSION_LIMIT,
                time_limit: Optional[float] = None, seed: int = 0, anytime: bool = True) -> MapfResult:
    """Search the agents' joint configurations in the manner of LaCAM*; a
    :class:`~agents.search.mapf.result.MapfResult` (``solver`` ``"lacam"``).

    Guarantees: complete (with an unlimited budget it finds a plan where one exists, and reports
    ``"infeasible"`` where none does, once the configurations reachable from the starts are
    exhausted) and, with ``anytime``, eventually optimal in the sum of costs (status
    ``"optimal"`` once no node below the best cost is left, or where the cost equals the sum of
    the agents' distances). It does not bound the cost of a first solution, and proving
    optimality or infeasibility takes the whole configuration space below the best cost: in
    reach with a handful of agents on a small graph only. See :mod:`agents.search.mapf.lacam`.

    Args:
        inst: the instance (either time model, with or without proximity).
        expansion_limit: the work budget of the whole solve: agents placed and candidate moves
            examined by the successor generator, low-level constraints made and edges relaxed
            when costs-to-come are repaired (``None``: no limit; then an instance too large to
            exhaust runs until the optimum is proven, which may be never). Reaching it ends the
            solve with the best plan so far (``"suboptimal"``) or ``"timeout"``.
        time_limit: wall-clock seconds, a safety net (``None``, the default: none).
        seed: seeds the tie-breaks (between equally good moves, and the order in which the
            low-level constraints are tried); the same seed, the same result.
        anytime: after the first solution, go on improving it until the budget ends or it is
            proven optimal (``False``: return the first solution).

    Returns:
        status ``"optimal"`` (proven: search exhausted below the cost, or the cost equals the lower
        bound), ``"suboptimal"`` (a plan, not proven optimal), ``"timeout"`` (the budget ended
        before any plan; the message says which limit) or ``"infeasible"`` (an agent cannot reach
        its goal even alone, two starts or two goals are within the proximity radius of each
        other, or the search exhausted every reachable configuration). ``work``: the work counted
        against ``expansion_limit``; ``stats``: a :class:`ConfigurationStats`.
    """
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    check_common_options(expansion_limit, time_limit, 0)
    run = SolveRun(expansion_limit, time_limit, "lacam", ConfigurationStats())
    k = inst.n_agents
    reason = (_overlap(inst, inst.starts, "start") or _overlap(inst, inst.goals, "goal")
              or no_plan_reason(inst, 0))
    if reason is not None:
        return run.finish(inst, MapfResult("infeasible", message=reason))
    lb = sum(inst.h[i][inst.starts[i]] for i in range(k))
    rng = random.Random(seed)
    gen: Union[_UnitGen, _OccGen]
    if inst.unit and inst.near is None:
        gen = _UnitGen(inst, rng, run.counter)
        root_state: tuple = (tuple(inst.starts), None, None)
    else:
        gen = _OccGen(inst, rng, run.counter)
        root_state = (tuple(inst.starts), (-1,) * k, (0,) * k)
    search = _Search(inst, gen, rng, run, anytime)
    limit = sys.getrecursionlimit()
    if limit < 4 * k + 100:
        sys.setrecursionlimit(4 * k + 100)
    stopped = ""
    try:
        search.add(None, root_state, ())
        exhausted = search.search()
    except (BudgetExceeded, TimeoutError) as exc:
        exhausted = False
        stopped = (f"expansion limit of {expansion_limit}" if isinstance(exc, BudgetExceeded)
                   else f"time limit of {time_limit:g} s")
    finally:
        sys.setrecursionlimit(limit)
    stats = run.stats
    stats.configurations = search.generated
    stats.generations = search.expanded
    stats.generator_calls = gen.calls
    plan = search.plan
    where = f"{search.generated} configurations, {search.expanded} successor generations"
    if plan is None:
        if exhausted:
            return run.finish(inst, MapfResult("infeasible", lower_bound=lb, message=(
                f"no plan exists: the search exhausted every configuration reachable from the starts ({where})")))
        return run.finish(inst, MapfResult("timeout", lower_bound=lb, message=(
            f"{stopped} reached before a plan was found (configuration search, {where})")))
    paths = search.paths(plan)
    if exhausted:
        soc = sum(p[-1][1] for p in paths)
        res = MapfResult("optimal", paths, soc, max((p[-1][1] for p in paths), default=0), soc,
                        message=f"proven optimal: no configuration below its cost is left ({where})")
        return run.finish(inst, res)
    why = f"{stopped} reached" if stopped else "first solution"
    return run.finish(inst, plan_result(paths, lb, f"{why}; optimality not proven ({where})"))
