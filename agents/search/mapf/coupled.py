"""The coupled search of a meta-agent: optimal joint paths of a small group of agents (unit time).

Meta-agent CBS (MA-CBS) merges agents that keep conflicting into one *meta-agent* planned by a
coupled search. :func:`coupled_astar` is that search: A* with operator decomposition over the
group's joint moves. A full state holds every member's node at time ``t`` and which members
have *finished* (made their final arrival: they stay at their goal for good and pay nothing
more); an intermediate state has the first ``j`` members already moved to time ``t + 1``. Each
step, every member that has not finished pays one, so the cost of a joint plan is the sum of
its members' final arrival times (their sum of costs), exactly the CBS cost.

The members' own CBS constraints (each compiled for the low level) are respected, and the
members never collide with each other: vertex, swap and proximity conflicts, and no member
may pass over a finished member's goal. Among the cheapest joint plans, the search prefers
the ones with the fewest conflicts with the other agents' paths (a
:class:`~agents.search.mapf.paths.Reservation`), as the single-agent low level does.

States later than the members' constraint and reservation horizon are merged per joint
configuration, so the search terminates; when it closes every reachable state without
finishing, no joint plan meets the constraints (the members alone prove the node, or the
instance, infeasible). It stops with :class:`CoupledLimit` after ``max_states`` expansions.
"""
from __future__ import annotations

import heapq
import time as _time
from typing import Dict, List, Optional, Sequence, Tuple

from .constraints import CompiledConstraints
from .instance import UNREACHABLE, MapfInstance
from .lowlevel import Counter, Events, SearchTimeout
from .paths import Reservation
from .successors import CLOCK_CHECK_MASK, EMPTY_RESERVATION


class CoupledLimit(Exception):
    """The coupled search expanded ``max_states`` states without an answer.

    ``bound``: a lower bound on the optimal sum of costs, the ``f`` of the last state expanded
    (the heuristic, each member's distance to its goal raised to its goal constraints, is
    consistent, so A* expands states in order of non-decreasing ``f`` and every one up to the
    optimum); 0 when not known.
    """

    def __init__(self, bound: int = 0) -> None:
        super().__init__(bound)
        self.bound = bound


#: a search node: (time of the moved members, j, positions, old positions of the first j,
#: finished mask, parent node or None)
_Node = Tuple[int, int, Tuple[int, ...], Tuple[int, ...], int, Optional[tuple]]


def coupled_astar(
    inst: MapfInstance,
    agents: Sequence[int],
    ccs: Sequence[CompiledConstraints],
    res: Optional[Reservation],
    deadline: float,
    counter: Counter,
    max_states: int = 100_000,
) -> Optional[List[Events]]:
    """Optimal joint paths of ``agents`` (global ids) under their compiled constraints ``ccs``.

    Unit time only. Returns per member the events ``[(node, time), ...]`` up to its final
    arrival (the member stays at its goal afterwards), with the smallest sum of final arrival
    times and, among those, the fewest conflicts with ``res``; or ``None`` when no joint plan
    meets the constraints. Raises :class:`CoupledLimit` past ``max_states`` expansions and
    :class:`~agents.search.mapf.lowlevel.SearchTimeout` past ``deadline``.
    """
    if not inst.unit:
        raise ValueError("the coupled search supports the unit time model only")
    counter.calls += 1
    k = len(agents)
    N = inst.n_nodes
    succ = inst.succ
    near = inst.near_mat
    starts = tuple(inst.starts[a] for a in agents)
    goals = tuple(inst.goals[a] for a in agents)
    hs = [inst.h[a] for a in agents]
    for m in range(k):
        cc = ccs[m]
        if cc.impossible or hs[m][starts[m]] >= UNREACHABLE or starts[m] in cc.vset:
            return None
        if cc.deadline <= cc.goal_min:
            return None
    gmin = [cc.goal_min for cc in ccs]
    dl = [cc.deadline for cc in ccs]
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else EMPTY_RESERVATION
    L = max(cc.t_static for cc in ccs)
    if res is not None:
        L = max(L, res.horizon)
    L += 1
    full = (1 << k) - 1

    def h_of(m: int, v: int, t: int) -> int:
        hv = hs[m][v]
        if t + hv <= gmin[m]:
            hv = gmin[m] + 1 - t
        return hv

    h0 = sum(h_of(m, starts[m], 0) for m in range(k))
    start: _Node = (0, 0, starts, (), 0, None)
    seq = 0
    heap: List[Tuple[int, int, int, int, _Node]] = [(h0, h0, 0, seq, start)]
    # key -> (g, conflicts) of the best entry pushed
    best: Dict[Tuple, Tuple[int, int]] = {(0, 0, starts, (), 0): (0, 0)}
    closed = set()
    pops = 0
    clock = CLOCK_CHECK_MASK
    while heap:
        f, hh, nc, _, node = heapq.heappop(heap)
        t, j, pos, old, done, _parent = node
        key = (min(t, L), j, pos, old, done)
        if key in closed:
            continue
        closed.add(key)
        g = f - hh
        if j == 0 and done == full:
            counter.expanded += pops
            return _events(node, k)
        pops += 1
        if pops > max_states:
            counter.expanded += pops
            raise CoupledLimit(f)
        if not pops & clock and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        # member j decides its move from time t to t + 1 (the first j have moved already)
        bit = 1 << j
        cc = ccs[j]
        u = pos[j]
        nt = t + 1
        h_rest = hh - (0 if done & bit else h_of(j, u, t))
        # the nodes the moved members (and the finished ones) hold at t + 1, for conflicts
        taken = pos[:j]
        later = [pos[m] for m in range(j + 1, k) if done >> m & 1]
        options: List[Tuple[int, int, int, int]] = []  # (node, finished mask, step cost, conflicts)
        if done & bit:
            options.append((u, done, 0, 0))
        else:
            if u == goals[j] and t > gmin[j] and t <= dl[j]:
                options.append((u, done | bit, 0, 0))  # final arrival at t: stays here for good
            vset, eset, forever = cc.vset, cc.eset, cc.forever
            vbase = nt * N
            src = (t * N + u) * N
            for w in succ[u]:
                if hs[j][w] >= UNREACHABLE or (vbase + w) in vset:
                    continue
                if nt + hs[j][w] > dl[j]:
                    continue
                dc = 0
                if w != u:
                    if (src + w) in eset:
                        continue
                    if ((t * N + w) * N + u) in moves:
                        dc += 1
                if forever:
                    fw = forever.get(w)
                    if fw is not None and nt >= fw:
                        continue
                if (vbase + w) in occ:
                    dc += 1
                if parked:
                    pt = parked.get(w)
                    if pt is not None and nt >= pt:
                        dc += 1
                options.append((w, done, 1, dc))
        for w, ndone, cost, dc in options:
            # conflicts with the members that moved already, and the finished ones still to come
            bad = False
            for i in range(j):
                x = taken[i]
                if x == w or (near is not None and near[x, w]):
                    bad = True
                    break
                if w != u and x == u and old[i] == w:
                    bad = True  # swap
                    break
            if bad:
                continue
            for x in later:
                if x == w or (near is not None and near[x, w]):
                    bad = True
                    break
            if bad:
                continue
            npos = pos[:j] + (w,) + pos[j + 1:]
            child_old: Tuple[int, ...]
            if j + 1 == k:
                child_t, child_j, child_old = nt, 0, ()
            else:
                child_t, child_j, child_old = t, j + 1, old + (u,)
            ng = g + cost
            hw = 0 if ndone & bit else h_of(j, w, nt)
            nh = h_rest + hw
            nnc = nc + dc
            ckey = (min(child_t, L), child_j, npos, child_old, ndone)
            if ckey in closed:
                continue
            prev = best.get(ckey)
            if prev is not None and prev <= (ng, nnc):
                continue
            best[ckey] = (ng, nnc)
            seq += 1
            heapq.heappush(heap, (ng + nh, nh, nnc, seq, (child_t, child_j, npos, child_old, ndone, node)))
    counter.expanded += pops
    return None


def _events(node: tuple, k: int) -> List[Events]:
    """Per member, its timed path up to its final arrival, from the goal node's parent chain.

    A member first marked finished in the full state at time ``t + 1`` made its final arrival
    at ``t``: its events end there.
    """
    chain = []
    cur: Optional[tuple] = node
    while cur is not None:
        if cur[1] == 0:
            chain.append(cur)
        cur = cur[5]
    chain.reverse()  # full states at times 0, 1, ..., T (the last one with every member finished)
    out: List[Events] = []
    for m in range(k):
        ev: Events = []
        for t, _, pos, _, done, _ in chain:
            if done >> m & 1:
                break
            ev.append((pos[m], t))
        out.append(ev)
    return out
