"""The low level of CBS: timed paths, space-time A*, focal search, MDDs and conflict detection.

States are ``(node, time)`` pairs encoded as integers ``time * N + node``. Each agent's
constraints are compiled to integer sets (:func:`~agents.search.constraints.compile_constraints`);
the other agents' paths are summarised in a :class:`Reservation` (integer sets) used to break
ties towards fewer conflicts. Conflict detection between two paths intersects their integer
code sets, so it runs at C speed.

Time semantics (see :mod:`agents.search.constraints`):

- unit time: an agent is at one node at each integer time; vertex, swap, proximity (at integer
  times) and target conflicts.
- durative: during each step ``[k, k + 1)`` an agent *occupies* one node (waiting) or both ends
  of the edge it is traversing. Two agents conflict when their occupied nodes coincide or are
  near. This is deliberately conservative: an agent may not enter a node during the step
  another agent is leaving it, and swaps or crossings of edges are vertex conflicts.

In both models an agent stays at its goal forever after its final arrival (it is *parked*).
"""
from __future__ import annotations

import heapq
import time as _time
from typing import Callable, Dict, List, Optional, Sequence, Set, Tuple

from .constraints import (
    EDGE,
    PROXIMITY,
    TARGET,
    VERTEX,
    CompiledConstraints,
    Conflict,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
)
from .mapf_instance import UNREACHABLE, MapfInstance


class SearchTimeout(Exception):
    """Raised inside the search when the wall-clock deadline passes."""


# ---------------------------------------------------------------------------------- paths
class AgentPath:
    """One agent's timed path and the integer indexes used by conflict detection.

    ``events`` lists ``(node, time)`` at every time the agent is at a node: each time step
    under unit time; arrivals and each waiting step under the durative model. The last event is
    the final arrival at the goal; ``cost`` is its time.
    """

    __slots__ = ("events", "cost", "goal", "steps", "codes", "code_set", "move_codes", "swap_set",
                 "node_set", "near_codes", "occ", "lb")

    def __init__(self, events: List[Tuple[int, int]], inst: MapfInstance, lb: Optional[int] = None):
        N = inst.n_nodes
        self.events = events
        self.goal, self.cost = events[-1]
        T = self.cost
        #: lower bound on this agent's optimal cost under its constraints (focal search)
        self.lb = T if lb is None else lb
        if inst.unit:
            steps = [v for v, _ in events]
            self.steps = steps
            self.occ = None
            self.codes = [t * N + steps[t] for t in range(T)]
            mc = []
            sw = []
            for t in range(T):
                u, w = steps[t], steps[t + 1]
                if u != w:
                    mc.append((t * N + u) * N + w)
                    sw.append((t * N + w) * N + u)
            self.move_codes = mc
            self.swap_set = set(sw)
            self.node_set = set(steps)
            occ_pairs = [(t, steps[t]) for t in range(T)]
        else:
            occ: List[Tuple[int, int]] = []  # per step k < T: (node, other end or same)
            for (u, t0), (v, t1) in zip(events, events[1:]):
                for _ in range(t0, t1):
                    occ.append((u, v))
            self.occ = occ
            self.steps = None
            codes = []
            occ_pairs = []
            for k, (u, v) in enumerate(occ):
                codes.append(k * N + u)
                occ_pairs.append((k, u))
                if v != u:
                    codes.append(k * N + v)
                    occ_pairs.append((k, v))
            self.codes = codes
            self.move_codes = []
            self.swap_set = set()
            self.node_set = {v for v, _ in events}
        self.code_set = set(self.codes)
        near = inst.near
        if near is not None:
            nc = []
            for k, x in occ_pairs:
                base = k * N
                nc.extend(base + y for y in near[x])
            self.near_codes = nc
        else:
            self.near_codes = None

    def node_at(self, t: int) -> int:
        """Unit time: the node at time ``t`` (the goal after arrival)."""
        return self.steps[t] if t < len(self.steps) else self.goal

    def occupied(self, k: int) -> Tuple[int, ...]:
        """Nodes occupied during step ``k`` (durative) / at time ``k`` (unit)."""
        if self.occ is None:
            return (self.node_at(k),)
        if k >= self.cost:
            return (self.goal,)
        u, v = self.occ[k]
        return (u,) if u == v else (u, v)


class Reservation:
    """The other agents' paths as integer sets, for conflict-avoiding tie-breaking."""

    __slots__ = ("occ", "moves", "parked", "horizon")

    def __init__(self, paths: Sequence[Optional[AgentPath]], exclude: int, inst: MapfInstance):
        occ: Set[int] = set()
        moves: Set[int] = set()
        parked: Dict[int, int] = {}
        horizon = 0
        near = inst.near
        for b, p in enumerate(paths):
            if b == exclude or p is None:
                continue
            occ.update(p.codes)
            if p.move_codes:
                moves.update(p.move_codes)
            if p.near_codes is not None:
                occ.update(p.near_codes)
            T = p.cost
            if T > horizon:
                horizon = T
            for x in ([p.goal] + near[p.goal]) if near is not None else (p.goal,):
                old = parked.get(x)
                if old is None or T < old:
                    parked[x] = T
        self.occ = occ
        self.moves = moves
        self.parked = parked
        self.horizon = horizon


_EMPTY_RES_SETS: Tuple[Set[int], Set[int], Dict[int, int]] = (set(), set(), {})


# ---------------------------------------------------------------------------------- successors
Expander = Callable[[int, int], List[Tuple[int, int, int]]]


def make_expander(inst: MapfInstance, cc: CompiledConstraints, res: Optional[Reservation]) -> Expander:
    """``expand(v, t) -> [(w, t_arrival, n_conflicts), ...]`` under the constraints ``cc``."""
    N = inst.n_nodes
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else _EMPTY_RES_SETS
    if inst.unit:
        succ = inst.succ

        def expand(v: int, t: int) -> List[Tuple[int, int, int]]:
            nt = t + 1
            base = nt * N
            src = (t * N + v) * N
            out = []
            for w in succ[v]:
                code = base + w
                if code in vset:
                    continue
                if w != v:
                    if (src + w) in eset:
                        continue
                    dc = 1 if ((t * N + w) * N + v) in moves else 0
                else:
                    dc = 0
                if forever:
                    fw = forever.get(w)
                    if fw is not None and nt >= fw:
                        continue
                if code in occ:
                    dc += 1
                if parked:
                    pt = parked.get(w)
                    if pt is not None and nt >= pt:
                        dc += 1
                out.append((w, nt, dc))
            return out

        return expand

    succ_d = inst.succ_d

    def expand_d(v: int, t: int) -> List[Tuple[int, int, int]]:
        out = []
        fv = forever.get(v) if forever else None
        pv = parked.get(v) if parked else None
        for w, d in succ_d[v]:
            nt = t + d
            last = nt - 1
            if fv is not None and last >= fv:
                continue
            ok = True
            dc = 0
            same = w == v
            for k in range(t, nt):
                kb = k * N
                if (kb + v) in vset or (not same and (kb + w) in vset):
                    ok = False
                    break
                if (kb + v) in occ:
                    dc += 1
                if not same and (kb + w) in occ:
                    dc += 1
            if not ok:
                continue
            if not same:
                if forever:
                    fw = forever.get(w)
                    if fw is not None and last >= fw:
                        continue
                if parked:
                    pw = parked.get(w)
                    if pw is not None and last >= pw:
                        dc += 1
            if pv is not None and last >= pv:
                dc += 1
            out.append((w, nt, dc))
        return out

    return expand_d


def _horizon(cc: CompiledConstraints, res: Optional[Reservation]) -> int:
    """After this time, states at the same node are interchangeable (nothing changes anymore)."""
    h = cc.t_static
    if res is not None and res.horizon > h:
        h = res.horizon
    return h + 1


def _landmarks(inst: MapfInstance, agent: int, cc: CompiledConstraints) -> Dict[int, List[Tuple[int, int, int]]]:
    """For finite range constraints on a node B: node -> [(start, end, bound)] for the nodes whose
    every path to the goal crosses B; from such a node at a time in [start, end] the final
    arrival is at least ``bound = end + 1 + h(B)`` (B is closed until ``end``). Cached on ``cc``."""
    lm = getattr(cc, "_landmarks", None)
    if lm is None:
        lm = {}
        h = inst.h[agent]
        g = inst.goals[agent]
        for node, lo, hi in cc.ranges:
            hb = h[node]
            if hb >= UNREACHABLE:
                continue
            entry = (lo, hi, hi + 1 + hb)
            for v in inst.must_pass(g, node):
                lm.setdefault(v, []).append(entry)
        cc._landmarks = lm
    return lm


_NO_FOREVER: Tuple[int, Optional[List[int]], Optional[List[int]]] = (1 << 62, None, None)


def _forever_h(inst: MapfInstance, agent: int, cc: CompiledConstraints):
    """Unit time: ``(TF, hF, late)`` for the "never again" constraints of ``cc`` (cached on ``cc``).

    From time ``TF`` on every such node is closed for good, and ``hF`` holds the distances to the
    goal avoiding them. ``late[v]`` is the last time at which being at ``v`` can still lead to the
    goal: from a node that reaches the goal only through a closed node ``x``, the last visit to
    such a node must come before it closes, so ``t + dist(v, x) <= fw(x) - 1`` for some ``x``.
    """
    if not cc.forever:
        return _NO_FOREVER
    out = getattr(cc, "_forever_h", None)
    if out is None:
        out = cc._forever_h = _cut_off(inst, inst.goals[agent], frozenset(), cc.forever)
    return out


def _reconstruct(code: int, parent: Dict[int, int], tclose: Dict[int, int], N: int) -> List[Tuple[int, int]]:
    out = []
    while code >= 0:
        out.append((code % N, tclose[code]))
        code = parent[code]
    out.reverse()
    return out


def _hstart(hs: int, gl: int, lm, s: int) -> int:
    """The time-aware heuristic of the start state (time 0)."""
    if hs < gl:
        hs = gl
    if lm is not None:
        for lo, hi, bound in lm.get(s, ()):
            if lo <= 0 <= hi and hs < bound:
                hs = bound
    return hs


class Counter:
    """Low-level statistics shared by all searches of one solve."""

    __slots__ = ("expanded", "calls")

    def __init__(self):
        self.expanded = 0
        self.calls = 0


def space_time_astar(
    inst: MapfInstance,
    agent: int,
    cc: CompiledConstraints,
    res: Optional[Reservation],
    deadline: float,
    counter: Counter,
) -> Optional[List[Tuple[int, int]]]:
    """Cheapest timed path of ``agent`` under ``cc``, fewest conflicts with ``res`` among those.

    Returns the events ``[(node, time), ...]`` ending with the final arrival at the goal, or
    ``None`` when no path satisfies the constraints. States later than the constraint and
    reservation horizon are merged per node, so the search always terminates.
    """
    counter.calls += 1
    if cc.impossible:
        return None
    N = inst.n_nodes
    h = inst.h[agent]
    s, g = inst.starts[agent], inst.goals[agent]
    hs = h[s]
    if hs >= UNREACHABLE:
        return None
    goal_min = cc.goal_min
    if inst.unit and s in cc.vset:
        return None
    gl = goal_min + 1
    lm = _landmarks(inst, agent, cc) if cc.ranges else None
    hs = _hstart(hs, gl, lm, s)
    L = _horizon(cc, res)
    if inst.unit:
        return _astar_unit(inst, agent, cc, res, deadline, counter, hs, gl, lm, L)
    expand = make_expander(inst, cc, res)
    heap = [(hs, 0, hs, s)]
    best = {s: hs << 24}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    pops = 0
    pop = heapq.heappop
    push = heapq.heappush
    while heap:
        f, c, hh, code = pop(heap)
        if code in tclose:
            continue
        t = f - hh
        tclose[code] = t
        v = code % N
        if v == g and t > goal_min:
            counter.expanded += pops
            return _reconstruct(code, parent, tclose, N)
        pops += 1
        if not pops & 1023 and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        for w, nt, dc in expand(v, t):
            hw = h[w]
            if hw >= UNREACHABLE:
                continue
            if nt + hw < gl:
                hw = gl - nt
            if lm is not None:
                lst = lm.get(w)
                if lst is not None:
                    for lo, hi, bound in lst:
                        if lo <= nt <= hi and nt + hw < bound:
                            hw = bound - nt
            ncode = (nt if nt < L else L) * N + w
            if ncode in tclose:
                continue
            nc = c + dc
            nf = nt + hw
            pk = (nf << 24) | nc
            old = best.get(ncode)
            if old is not None and old <= pk:
                continue
            best[ncode] = pk
            parent[ncode] = code
            push(heap, (nf, nc, hw, ncode))
    counter.expanded += pops
    return None


def _hsucc(inst: MapfInstance, agent: int) -> List[List[Tuple[int, int]]]:
    """Per node, ``(successor, its distance to the agent's goal)`` for the successors (wait first)
    from which the goal can be reached (cached on the instance)."""
    cache = inst.__dict__.setdefault("_hsucc_cache", {})
    out = cache.get(agent)
    if out is None:
        h = inst.h[agent]
        out = [[(w, h[w]) for w in ws if h[w] < UNREACHABLE] for ws in inst.succ]
        cache[agent] = out
    return out


def _astar_unit(inst: MapfInstance, agent: int, cc: CompiledConstraints, res: Optional[Reservation],
                deadline: float, counter: Counter, hs: int, gl: int, lm, L: int) -> Optional[List[Tuple[int, int]]]:
    """:func:`space_time_astar` under unit time, with the successor generation inlined.

    Open entries are single integers ``f | conflicts | h | code`` (bit fields, most significant
    first), so the heap compares plain integers in the order of ``(f, conflicts, h, code)``.
    """
    N = inst.n_nodes
    s, g = inst.starts[agent], inst.goals[agent]
    goal_min = cc.goal_min
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else _EMPTY_RES_SETS
    hsucc = _hsucc(inst, agent)
    S1 = ((L + 1) * N).bit_length()  # codes are below (L + 1) * N
    MASK = (1 << S1) - 1
    S2 = S1 + 24
    S3 = S2 + 24
    FMASK = (1 << 24) - 1
    # from the time every "never again" constraint holds on, the agent moves in the graph without
    # those nodes: its distances there are a stronger admissible heuristic, and infinite where
    # the goal is cut off (which proves infeasibility without sweeping the whole horizon)
    TF, hF, late = _forever_h(inst, agent, cc)
    if late is not None and late[s] < 0:
        return None
    heap = [(hs << S3) | (hs << S1) | s]
    best = {s: hs << 24}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    pops = 0
    pop = heapq.heappop
    push = heapq.heappush
    LN = L * N
    NN = N * N
    while heap:
        key = pop(heap)
        code = key & MASK
        if code in tclose:
            continue
        hh = (key >> S1) & FMASK
        c = (key >> S2) & FMASK
        t = (key >> S3) - hh
        tclose[code] = t
        v = code % N
        if v == g and t > goal_min:
            counter.expanded += pops
            return _reconstruct(code, parent, tclose, N)
        pops += 1
        if not pops & 1023 and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        nt = t + 1
        vbase = nt * N
        base = vbase if nt < L else LN
        tNN = t * NN
        src = tNN + v * N
        for w, hw in hsucc[v]:
            ncode = base + w
            if ncode in tclose:
                continue
            vc = vbase + w
            if vc in vset:
                continue
            if w != v:
                if (src + w) in eset:
                    continue
                dc = 1 if (tNN + w * N + v) in moves else 0
            else:
                dc = 0
            if forever:
                fw = forever.get(w)
                if (fw is not None and nt >= fw) or nt > late[w]:
                    continue
                if nt >= TF:
                    hw = hF[w]
                    if hw >= UNREACHABLE:
                        continue
            if vc in occ:
                dc += 1
            if parked:
                pt = parked.get(w)
                if pt is not None and nt >= pt:
                    dc += 1
            if nt + hw < gl:
                hw = gl - nt
            if lm is not None:
                lst = lm.get(w)
                if lst is not None:
                    for lo, hi, bound in lst:
                        if lo <= nt <= hi and nt + hw < bound:
                            hw = bound - nt
            nc = c + dc
            nf = nt + hw
            pk = (nf << 24) | nc
            old = best.get(ncode)
            if old is not None and old <= pk:
                continue
            best[ncode] = pk
            parent[ncode] = code
            push(heap, (nf << S3) | (nc << S2) | (hw << S1) | ncode)
    counter.expanded += pops
    return None


def focal_search(
    inst: MapfInstance,
    agent: int,
    cc: CompiledConstraints,
    res: Optional[Reservation],
    w: float,
    deadline: float,
    counter: Counter,
) -> Optional[Tuple[List[Tuple[int, int]], int]]:
    """Bounded-suboptimal low level of ECBS: a path of cost <= ``w`` x optimal, few conflicts.

    Among the open states whose ``f`` is within ``w`` times the smallest open ``f`` (the
    focal list) it expands the one with the fewest conflicts with ``res``. Returns
    ``(events, lower_bound)`` where ``lower_bound`` <= the optimal cost under ``cc``.
    """
    counter.calls += 1
    if cc.impossible:
        return None
    N = inst.n_nodes
    h = inst.h[agent]
    s, g = inst.starts[agent], inst.goals[agent]
    hs = h[s]
    if hs >= UNREACHABLE:
        return None
    goal_min = cc.goal_min
    if inst.unit and s in cc.vset:
        return None
    gl = goal_min + 1
    lm = _landmarks(inst, agent, cc) if cc.ranges else None
    hs = _hstart(hs, gl, lm, s)
    L = _horizon(cc, res)
    expand = make_expander(inst, cc, res)
    pop, push = heapq.heappop, heapq.heappush
    best = {s: hs << 24}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    open_f = [(hs, s)]                 # every open entry, by f (for the lower bound)
    focal = [(0, hs, -0, s, hs)]       # entries with f <= bound, by conflicts then f
    pending: List[Tuple[int, int, int, int]] = []  # entries with f > bound, by f
    bound = w * hs
    pops = 0
    while True:
        while open_f and (open_f[0][1] in tclose or (best[open_f[0][1]] >> 24) != open_f[0][0]):
            pop(open_f)
        if not open_f:
            counter.expanded += pops
            return None
        fmin = open_f[0][0]
        if w * fmin > bound:
            bound = w * fmin
            while pending and pending[0][0] <= bound:
                f, c, hh, code = pop(pending)
                push(focal, (c, f, -(f - hh), code, hh))
        # pop the best focal entry that is still open and current
        while focal:
            c, f, negt, code, hh = pop(focal)
            if code in tclose or best[code] != ((f << 24) | c):
                continue
            break
        else:
            # every current entry is pending: widen the bound to the smallest f
            continue
        t = f - hh
        tclose[code] = t
        v = code % N
        if v == g and t > goal_min:
            counter.expanded += pops
            lb = max(fmin, goal_min + 1)
            return _reconstruct(code, parent, tclose, N), min(lb, t)
        pops += 1
        if not pops & 1023 and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        for x, nt, dc in expand(v, t):
            hx = h[x]
            if hx >= UNREACHABLE:
                continue
            if nt + hx < gl:
                hx = gl - nt
            if lm is not None:
                lst = lm.get(x)
                if lst is not None:
                    for lo, hi, bound in lst:
                        if lo <= nt <= hi and nt + hx < bound:
                            hx = bound - nt
            ncode = (nt if nt < L else L) * N + x
            if ncode in tclose:
                continue
            nc = c + dc
            nf = nt + hx
            pk = (nf << 24) | nc
            old = best.get(ncode)
            if old is not None and old <= pk:
                continue
            best[ncode] = pk
            parent[ncode] = code
            push(open_f, (nf, ncode))
            if nf <= bound:
                push(focal, (nc, nf, -nt, ncode, hx))
            else:
                push(pending, (nf, nc, hx, ncode))


def earliest_arrival(
    inst: MapfInstance,
    agent: int,
    cc: CompiledConstraints,
    target: int,
    blocked: frozenset,
    deadline: float,
    counter: Counter,
) -> int:
    """Earliest time ``agent`` can be at ``target`` under ``cc`` without entering ``blocked`` (unit time).

    Returns ``UNREACHABLE`` if it never can. Used to size corridor constraints.
    """
    N = inst.n_nodes
    hd = inst.dist_to(target, blocked)
    s = inst.starts[agent]
    if hd[s] >= UNREACHABLE:
        return UNREACHABLE
    if s == target:
        return 0
    L = cc.t_static + 1
    if inst.unit:
        return _earliest_unit(inst, cc, s, target, blocked, hd, L, deadline, counter)
    expand = make_expander(inst, cc, None)
    heap = [(hd[s], hd[s], s)]
    closed: Set[int] = set()
    pops = 0
    while heap:
        f, hv, code = heapq.heappop(heap)
        if code in closed:
            continue
        closed.add(code)
        v = code % N
        t = f - hv
        if v == target:
            counter.expanded += pops
            return t
        pops += 1
        if not pops & 1023 and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        for w, nt, _ in expand(v, t):
            hw = hd[w]
            if hw >= UNREACHABLE or w in blocked:
                continue
            ncode = (nt if nt < L else L) * N + w
            if ncode not in closed:
                heapq.heappush(heap, (nt + hw, hw, ncode))
    counter.expanded += pops
    return UNREACHABLE


def _cut_off(inst: MapfInstance, target: int, blocked: frozenset, closing: Dict[int, int]):
    """``(TF, hF, late)`` for reaching ``target`` avoiding ``blocked`` when each node ``x`` of
    ``closing`` is closed for good from time ``closing[x]`` (unit time; see :func:`_forever_h`)."""
    hF = inst.dist_to(target, blocked | frozenset(closing))
    late = [UNREACHABLE] * inst.n_nodes
    cut = [v for v in range(inst.n_nodes) if hF[v] >= UNREACHABLE]
    if cut:
        to_x = [(fw - 1, inst.dist_to(x)) for x, fw in closing.items()]
        for v in cut:
            late[v] = max(lim - d[v] for lim, d in to_x)
    return max(closing.values()), hF, late


def _earliest_unit(inst: MapfInstance, cc: CompiledConstraints, s: int, target: int, blocked: frozenset,
                   hd: List[int], L: int, deadline: float, counter: Counter) -> int:
    """:func:`earliest_arrival` under unit time (successors inlined, "never again" cut-offs)."""
    N = inst.n_nodes
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    closing = {x: fw for x, fw in forever.items() if x != target and x not in blocked}
    if closing:
        cache = getattr(cc, "_cut_offs", None)
        if cache is None:
            cache = cc._cut_offs = {}
        key = (target, blocked)
        out = cache.get(key)
        if out is None:
            out = cache[key] = _cut_off(inst, target, blocked, closing)
        TF, hF, late = out
        if late[s] < 0:
            return UNREACHABLE
    else:
        TF, hF, late = 1 << 62, None, None
    succ = inst.succ
    M = (L + 1) * N
    B = 1 << 30
    BM = B * M
    LN = L * N
    heap = [hd[s] * BM + hd[s] * M + s]
    closed: Set[int] = set()
    pops = 0
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        key = pop(heap)
        code = key % M
        if code in closed:
            continue
        closed.add(code)
        v = code % N
        rest = key // M
        hv = rest % B
        t = rest // B - hv
        if v == target:
            counter.expanded += pops
            return t
        pops += 1
        if not pops & 1023 and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        nt = t + 1
        vb = nt * N
        base = vb if nt < L else LN
        src = (t * N + v) * N
        for w in succ[v]:
            hw = hd[w]
            if hw >= UNREACHABLE or w in blocked or (vb + w) in vset:
                continue
            if w != v and (src + w) in eset:
                continue
            if forever:
                fw = forever.get(w)
                if fw is not None and nt >= fw:
                    continue
                if late is not None:
                    if nt > late[w]:
                        continue
                    if nt >= TF:
                        hw = hF[w]
                        if hw >= UNREACHABLE:
                            continue
            ncode = base + w
            if ncode not in closed:
                push(heap, (nt + hw) * BM + hw * M + ncode)
    counter.expanded += pops
    return UNREACHABLE


# ---------------------------------------------------------------------------------- MDDs
class MDD:
    """Multi-valued decision diagram: every (node, time) state on some cheapest path.

    Built for an agent, its constraints and its optimal cost ``C``. ``levels[t]`` is the set of
    nodes an optimal path can be at (unit time) at time ``t``; ``must[k]`` is the set of nodes
    *every* optimal path occupies at step ``k`` (durative) or is at (unit). ``edges`` lists the
    kept transitions ``(v, t, w, t2)``.
    """

    __slots__ = ("cost", "edges", "levels", "must", "_children", "start", "goal", "N", "_singles", "_kids")

    def __init__(self, cost: int, edges: List[Tuple[int, int, int, int]], start: int, goal: int, N: int, unit: bool):
        self.cost = cost
        self.edges = edges
        self.start = start
        self.goal = goal
        self.N = N
        self._singles: Optional[List[Tuple[int, int]]] = None
        self._kids: Optional[Dict[int, List[int]]] = None
        self._children: Optional[Dict[int, List[int]]] = None
        levels: List[Set[int]] = [set() for _ in range(cost + 1)]
        levels[0].add(start)
        levels[cost].add(goal)
        for e in edges:
            levels[e[3]].add(e[2])
        self.levels = levels
        if unit:
            self.must = [lv if len(lv) == 1 else set() for lv in levels]
        else:
            must: List[Optional[Set[int]]] = [None] * cost
            for v, t, w, t2 in edges:
                pair = {v, w}
                for k in range(t, t2):
                    m = must[k]
                    must[k] = set(pair) if m is None else (m & pair)
            self.must = [m if m is not None else set() for m in must]

    def avoidable(self, node: int, start: int, unit: bool, end: Optional[int] = None) -> bool:
        """Whether some optimal path is never at / never occupies ``node`` at a step in ``[start, end]``.

        ``end=None`` means for ever (the agent stays parked at its goal after ``cost``).
        """
        N = self.N
        target = self.cost * N + self.goal
        hi = end if end is not None else (1 << 60)
        if self.goal == node and hi >= self.cost:
            return False  # parked there from ``cost`` on
        if start <= 0 <= hi and self.start == node:
            return False
        stack = [self.start]
        seen = {self.start}
        while stack:
            code = stack.pop()
            if code == target:
                return True
            t, v = divmod(code, N)
            for nxt in self.children.get(code, ()):
                if nxt in seen:
                    continue
                t2, w = divmod(nxt, N)
                if unit:
                    if w == node and start <= t2 <= hi:
                        continue
                else:
                    # occupies v and w during steps t .. t2 - 1
                    if (w == node or v == node) and t2 - 1 >= start and t <= hi:
                        continue
                seen.add(nxt)
                stack.append(nxt)
        return False

    @property
    def children(self) -> Dict[int, List[int]]:
        """State code ``t * N + v`` -> the codes ``t2 * N + w`` of its children (built on first use)."""
        if self._children is None:
            N = self.N
            children: Dict[int, List[int]] = {}
            for v, t, w, t2 in self.edges:
                k = t * N + v
                lst = children.get(k)
                if lst is None:
                    children[k] = [t2 * N + w]
                else:
                    lst.append(t2 * N + w)
            self._children = children
        return self._children

    def kids(self) -> Dict[int, List[int]]:
        """State code ``t * N + v`` -> the nodes of its children (built on first use)."""
        if self._kids is None:
            N = self.N
            kids: Dict[int, List[int]] = {}
            for v, t, w, _ in self.edges:
                k = t * N + v
                lst = kids.get(k)
                if lst is None:
                    kids[k] = [w]
                else:
                    lst.append(w)
            self._kids = kids
        return self._kids

    def singletons(self) -> List[Tuple[int, int]]:
        """``(time, node)`` of every level with a single node (unit time)."""
        if self._singles is None:
            self._singles = [(t, next(iter(lv))) for t, lv in enumerate(self.levels) if len(lv) == 1]
        return self._singles


def build_mdd(inst: MapfInstance, agent: int, cc: CompiledConstraints, cost: int) -> MDD:
    """The MDD of ``agent`` under ``cc`` for its optimal cost ``cost``."""
    N = inst.n_nodes
    h = inst.h[agent]
    s, g = inst.starts[agent], inst.goals[agent]
    fwd: List[Tuple[int, int, int, int]] = []
    if inst.unit:
        vset, eset, forever = cc.vset, cc.eset, cc.forever
        succ = inst.succ
        layer: Set[int] = {s}
        for t in range(cost):
            nt = t + 1
            vb = nt * N
            rem = cost - nt
            nxt: Set[int] = set()
            last = nt == cost
            for v in sorted(layer):
                src = (t * N + v) * N
                for w in succ[v]:
                    if h[w] > rem or (last and w != g) or (vb + w) in vset:
                        continue
                    if w != v and (src + w) in eset:
                        continue
                    if forever:
                        fw = forever.get(w)
                        if fw is not None and nt >= fw:
                            continue
                    nxt.add(w)
                    fwd.append((v, t, w, nt))
            layer = nxt
    else:
        expand = make_expander(inst, cc, None)
        layers: Dict[int, Set[int]] = {0: {s}}
        for t in range(cost):
            nodes = layers.get(t)
            if not nodes:
                continue
            for v in sorted(nodes):
                for w, nt, _ in expand(v, t):
                    if nt > cost or nt + h[w] > cost:
                        continue
                    if nt == cost and w != g:
                        continue
                    layers.setdefault(nt, set()).add(w)
                    fwd.append((v, t, w, nt))
    alive = {cost * N + g}
    kept = []
    for v, t, w, nt in reversed(fwd):
        if nt * N + w in alive:
            alive.add(t * N + v)
            kept.append((v, t, w, nt))
    kept.reverse()
    return MDD(cost, kept, s, g, N, inst.unit)


def prune_mdd(m: MDD, cc: CompiledConstraints) -> Optional[MDD]:
    """Unit time: the MDD of the same agent and cost under constraints ``cc`` that include the
    ones ``m`` was built under (``None`` if no path of that cost is left).

    Every path of cost ``m.cost`` that meets ``cc`` meets the older constraints too, so it is a
    path of ``m``: dropping the edges ``cc`` forbids and trimming what no longer joins the start
    to the goal gives exactly the MDD :func:`build_mdd` would build, at a fraction of the work.
    """
    N = m.N
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    alive = {m.start}
    fwd = []
    for e in m.edges:  # in order of time
        v, t, w, t2 = e
        if t * N + v not in alive or (t2 * N + w) in vset:
            continue
        if w != v and ((t * N + v) * N + w) in eset:
            continue
        if forever:
            fw = forever.get(w)
            if fw is not None and t2 >= fw:
                continue
        alive.add(t2 * N + w)
        fwd.append(e)
    target = m.cost * N + m.goal
    if target not in alive:
        return None
    back = {target}
    kept = []
    for e in reversed(fwd):
        v, t, w, t2 = e
        if t2 * N + w in back:
            back.add(t * N + v)
            kept.append(e)
    kept.reverse()
    return MDD(m.cost, kept, m.start, m.goal, N, True)


def satisfies(path: "AgentPath", c) -> bool:
    """Unit time: whether a path (parked at its goal after its arrival) meets constraint ``c``."""
    T = path.cost
    steps = path.steps
    if isinstance(c, VertexConstraint):
        return (steps[c.time] if c.time < T else path.goal) != c.node
    if isinstance(c, EdgeConstraint):
        t = c.time
        if t >= T:
            return True
        return not (steps[t] == c.u and steps[t + 1] == c.v)
    if isinstance(c, RangeConstraint):
        if c.node == path.goal and c.end >= T and c.end >= c.start:
            return False
        for t in range(c.start, min(c.end, T - 1) + 1):
            if steps[t] == c.node:
                return False
        return True
    if isinstance(c, LengthConstraint):
        return T > c.time
    raise TypeError(f"unknown constraint {c!r}")


def mdds_dependent(m1: MDD, m2: MDD, near_mat=None) -> bool:
    """Unit time: True if no pair of optimal paths (one from each MDD) is conflict-free.

    A joint breadth-first search over both MDDs level by level (an agent past its cost stays
    at its goal); used by the dependency graph heuristics.
    """
    N = m1.N
    T = max(m1.cost, m2.cost)
    k1, k2 = m1.kids(), m2.kids()
    c1, c2 = m1.cost, m2.cost
    g1, g2 = (m1.goal,), (m2.goal,)
    cur = {(m1.start, m2.start)}
    empty = ()
    for t in range(T):
        nxt = set()
        tN = t * N
        for a, b in cur:
            na = k1.get(tN + a, empty) if t < c1 else g1
            nb = k2.get(tN + b, empty) if t < c2 else g2
            for x in na:
                for y in nb:
                    if x == y or (x == b and y == a):
                        continue
                    if near_mat is not None and near_mat[x, y]:
                        continue
                    nxt.add((x, y))
        if not nxt:
            return True
        cur = nxt
    return not cur


# ---------------------------------------------------------------------------------- conflicts
def pair_conflicts(
    a: int, pa: AgentPath, b: int, pb: AgentPath, inst: MapfInstance, all_times: bool = True
) -> List[Conflict]:
    """All conflicts between the paths of agents ``a`` and ``b``, sorted by time.

    At most one conflict per time step is reported. Target conflicts (one agent parked at its
    goal) are reported once per direction, at the earliest time.
    """
    N = inst.n_nodes
    found: Dict[int, Conflict] = {}
    # both agents still moving
    common = pa.code_set.intersection(pb.codes)
    for code in common:
        t, x = divmod(code, N)
        if t not in found:
            found[t] = Conflict(VERTEX, a, b, t, x, x)
    if pa.swap_set and pb.move_codes:
        for code in pa.swap_set.intersection(pb.move_codes):
            tw, u = divmod(code, N)
            t, w = divmod(tw, N)
            # b moves w -> u at t, so a moves u -> w at t
            if t not in found:
                found[t] = Conflict(EDGE, a, b, t, u, w)
    near = inst.near
    if near is not None:
        if pa.near_codes:
            for code in pb.code_set.intersection(pa.near_codes):
                t, y = divmod(code, N)
                if t in found:
                    continue
                for x in pa.occupied(t):
                    if y in near[x]:
                        found[t] = Conflict(PROXIMITY, a, b, t, x, y)
                        break
    # one agent parked at its goal, the other still moving
    for (p, q, ip, iq) in ((pb, pa, b, a), (pa, pb, a, b)):
        # p parked at its goal from p.cost on; q moving before q.cost
        g, Tp = p.goal, p.cost
        if Tp >= q.cost:
            continue
        watch = {g} if near is None else ({g} | set(near[g]))
        if not (watch & q.node_set):
            continue
        for k in range(Tp, q.cost):
            hit = None
            for x in q.occupied(k):
                if x in watch:
                    hit = x
                    break
            if hit is not None:
                c = Conflict(TARGET, ip, iq, k, g, hit)
                old = found.get(k)
                if old is None or old.kind != TARGET:
                    found[k] = c
                break
    return [found[t] for t in sorted(found)]
