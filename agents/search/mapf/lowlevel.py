"""The low level of CBS: single-agent searches in space and time under one agent's constraints.

- :func:`space_time_astar`: the cheapest timed path, fewest conflicts with the other agents'
  paths among those (optimal CBS);
- :func:`focal_search`: a path of cost at most ``w`` times the cheapest, few conflicts (ECBS);
- :func:`earliest_arrival`: the earliest time an agent can be at a node (corridor reasoning).

States are ``(node, time)`` pairs encoded as integers ``time * N + node``. Each agent's
constraints arrive compiled to integer sets
(:func:`~agents.search.mapf.constraints.compile_constraints`); the other agents' paths are
summarised in a :class:`~agents.search.mapf.paths.Reservation` used to break ties towards
fewer conflicts. Under unit time the successors are generated inline (the hot loops of the
solver); under the durative model they come from
:func:`~agents.search.mapf.successors.make_expander`. Every search raises a successor's
heuristic with :func:`~agents.search.mapf.successors.time_aware_h` where the constraints prove
more than the distance to the goal.
"""
from __future__ import annotations

import heapq
import time as _time
from typing import Dict, List, Optional, Set, Tuple

from .constraints import CompiledConstraints
from .instance import UNREACHABLE, MapfInstance
from .paths import Reservation
from .successors import (
    CLOCK_CHECK_MASK,
    EMPTY_RESERVATION,
    FIELD_BITS,
    FIELD_MASK,
    H_RADIX,
    NEVER,
    SPREAD_SHIFT,
    Landmarks,
    cut_off,
    forever_h,
    goal_successors,
    horizon,
    landmarks,
    make_expander,
    time_aware_h,
)

#: A timed path: ``[(node, time), ...]`` ending with the final arrival at the goal.
Events = List[Tuple[int, int]]


class SearchTimeout(Exception):
    """Raised inside the search when the wall-clock deadline passes."""


class Counter:
    """Low-level statistics shared by all searches of one solve."""

    __slots__ = ("expanded", "calls")

    def __init__(self) -> None:
        self.expanded = 0
        self.calls = 0


def _reconstruct(code: int, parent: Dict[int, int], tclose: Dict[int, int], N: int) -> Events:
    out = []
    while code >= 0:
        out.append((code % N, tclose[code]))
        code = parent[code]
    out.reverse()
    return out


def space_time_astar(
    inst: MapfInstance,
    agent: int,
    cc: CompiledConstraints,
    res: Optional[Reservation],
    deadline: float,
    counter: Counter,
) -> Optional[Events]:
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
    lm = landmarks(inst, agent, cc) if cc.ranges else None
    hs = time_aware_h(s, 0, hs, gl, lm)
    if hs > cc.deadline:
        return None
    L = horizon(cc, res)
    if inst.unit:
        return _astar_unit(inst, agent, cc, res, deadline, counter, hs, gl, lm, L)
    expand = make_expander(inst, cc, res)
    fb, clock = FIELD_BITS, CLOCK_CHECK_MASK
    DL = cc.deadline
    heap = [(hs, 0, hs, s)]
    best = {s: hs << fb}
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
        if not pops & clock and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        for w, nt, dc in expand(v, t):
            hw = h[w]
            if hw >= UNREACHABLE:
                continue
            if nt + hw < gl or (lm is not None and w in lm):
                hw = time_aware_h(w, nt, hw, gl, lm)
            ncode = (nt if nt < L else L) * N + w
            if ncode in tclose:
                continue
            nc = c + dc
            nf = nt + hw
            if nf > DL:
                continue
            pk = (nf << fb) | nc
            old = best.get(ncode)
            if old is not None and old <= pk:
                continue
            best[ncode] = pk
            parent[ncode] = code
            push(heap, (nf, nc, hw, ncode))
    counter.expanded += pops
    return None


def _astar_unit(inst: MapfInstance, agent: int, cc: CompiledConstraints, res: Optional[Reservation],
                deadline: float, counter: Counter, hs: int, gl: int, lm: Optional[Landmarks],
                L: int) -> Optional[Events]:
    """:func:`space_time_astar` under unit time, with the successor generation inlined.

    Open entries are single integers ``f | conflicts | h | code`` (bit fields, most significant
    first; the conflict and heuristic fields are :data:`FIELD_BITS` wide, the code field just
    wide enough for the codes below ``(L + 1) * N``), so the heap compares plain integers in the
    order of ``(f, conflicts, h, code)``.
    """
    N = inst.n_nodes
    s, g = inst.starts[agent], inst.goals[agent]
    goal_min = cc.goal_min
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else EMPTY_RESERVATION
    hsucc = goal_successors(inst, agent)
    fb, fmask, clock = FIELD_BITS, FIELD_MASK, CLOCK_CHECK_MASK
    S1 = ((L + 1) * N).bit_length()  # shift of the heuristic field: codes are below (L + 1) * N
    MASK = (1 << S1) - 1
    S2 = S1 + fb  # shift of the conflict-count field
    S3 = S2 + fb  # shift of f
    # from the time every "never again" constraint holds on, the agent moves in the graph without
    # those nodes: its distances there are a stronger admissible heuristic, and infinite where
    # the goal is cut off (which proves infeasibility without sweeping the whole horizon)
    TF, hF_or_none, late_or_none = forever_h(inst, agent, cc)
    # both are None exactly when there is no "never again" constraint; the loop reads them only
    # when there is one
    hF: List[int] = hF_or_none if hF_or_none is not None else []
    late: List[int] = late_or_none if late_or_none is not None else []
    if late_or_none is not None and late[s] < 0:
        return None
    DL = cc.deadline
    heap = [(hs << S3) | (hs << S1) | s]
    best = {s: hs << fb}
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
        hh = (key >> S1) & fmask
        c = (key >> S2) & fmask
        t = (key >> S3) - hh
        tclose[code] = t
        v = code % N
        if v == g and t > goal_min:
            counter.expanded += pops
            return _reconstruct(code, parent, tclose, N)
        pops += 1
        if not pops & clock and _time.perf_counter() > deadline:
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
            if nt + hw < gl or (lm is not None and w in lm):
                hw = time_aware_h(w, nt, hw, gl, lm)
            nc = c + dc
            nf = nt + hw
            if nf > DL:
                continue
            pk = (nf << fb) | nc
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
) -> Optional[Tuple[Events, int]]:
    """Bounded-suboptimal low level of ECBS: a path of cost <= ``w`` x optimal, few conflicts.

    Among the open states whose ``f`` is within ``w`` times the smallest open ``f`` (the
    focal list) it expands the one with the fewest conflicts with ``res``, then the lowest ``f``,
    then (a reservation with ``places``) the fewest places entered. Returns
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
    lm = landmarks(inst, agent, cc) if cc.ranges else None
    hs = time_aware_h(s, 0, hs, gl, lm)
    L = horizon(cc, res)
    expand = make_expander(inst, cc, res)
    fb, clock = FIELD_BITS, CLOCK_CHECK_MASK
    pop, push = heapq.heappop, heapq.heappush
    best = {s: hs << fb}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    open_f = [(hs, s)]                 # every open entry, by f (for the lower bound)
    # entries with f <= bound, by conflicts, then f, then (spreading routes) places entered
    sh = SPREAD_SHIFT if res is not None and res.places else 0
    pm = (1 << sh) - 1
    focal = [(0, hs, 0, -0, s, hs)]
    pending: List[Tuple[int, int, int, int]] = []  # entries with f > bound, by f
    bound = w * hs
    pops = 0
    while True:
        while open_f and (open_f[0][1] in tclose or (best[open_f[0][1]] >> fb) != open_f[0][0]):
            pop(open_f)
        if not open_f:
            counter.expanded += pops
            return None
        fmin = open_f[0][0]
        if w * fmin > bound:
            bound = w * fmin
            while pending and pending[0][0] <= bound:
                f, c, hh, code = pop(pending)
                push(focal, (c >> sh, f, c & pm, -(f - hh), code, hh))
        # pop the best focal entry that is still open and current
        while focal:
            c, f, cp, negt, code, hh = pop(focal)
            c = (c << sh) | cp
            if code in tclose or best[code] != ((f << fb) | c):
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
        if not pops & clock and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        for x, nt, dc in expand(v, t):
            hx = h[x]
            if hx >= UNREACHABLE:
                continue
            if nt + hx < gl or (lm is not None and x in lm):
                hx = time_aware_h(x, nt, hx, gl, lm)
            ncode = (nt if nt < L else L) * N + x
            if ncode in tclose:
                continue
            nc = c + dc
            nf = nt + hx
            pk = (nf << fb) | nc
            old = best.get(ncode)
            if old is not None and old <= pk:
                continue
            best[ncode] = pk
            parent[ncode] = code
            push(open_f, (nf, ncode))
            if nf <= bound:
                push(focal, (nc >> sh, nf, nc & pm, -nt, ncode, hx))
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
    clock = CLOCK_CHECK_MASK
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
        if not pops & clock and _time.perf_counter() > deadline:
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


def _earliest_unit(inst: MapfInstance, cc: CompiledConstraints, s: int, target: int, blocked: frozenset,
                   hd: List[int], L: int, deadline: float, counter: Counter) -> int:
    """:func:`earliest_arrival` under unit time (successors inlined, "never again" cut-offs).

    Open entries are single integers ``(f * H_RADIX + h) * M + code`` with ``M = (L + 1) * N``,
    so the heap compares plain integers in the order of ``(f, h, code)``.
    """
    N = inst.n_nodes
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    closing = {x: fw for x, fw in forever.items() if x != target and x not in blocked}
    hF: List[int]
    late: Optional[List[int]]
    if closing:
        cache = cc.cut_offs
        if cache is None:
            cache = cc.cut_offs = {}
        cut_key = (target, blocked)
        out = cache.get(cut_key)
        if out is None:
            out = cache[cut_key] = cut_off(inst, target, blocked, closing)
        TF, hF, late = out
        if late[s] < 0:
            return UNREACHABLE
    else:
        TF, hF, late = NEVER, [], None  # hF is read only where late is set
    clock = CLOCK_CHECK_MASK
    succ = inst.succ
    M = (L + 1) * N
    B = H_RADIX
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
        if not pops & clock and _time.perf_counter() > deadline:
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
