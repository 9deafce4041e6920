"""The low level of CBS: single-agent searches in space and time under one agent's constraints.

- :func:`space_time_astar`: the cheapest timed path, fewest conflicts with the other agents'
  paths among those (optimal CBS);
- :func:`focal_search`: a path of cost at most ``w`` times the cheapest, few conflicts (ECBS);
- :func:`earliest_arrival`: the earliest time an agent can be at a node (corridor reasoning).

States are ``(node, time)`` pairs encoded as integers ``time * N + node``. Each agent's
constraints arrive compiled to integer sets
(:func:`~agents.search.mapf.constraints.compile_constraints`); the other agents' paths are
summarised in a :class:`~agents.search.mapf.paths.Reservation` used to break ties towards
fewer conflicts. All three searches, under both time models, take a state's successors (with
their conflicts and heuristic) from :func:`~agents.search.mapf.successors.make_successors`;
they differ in the order in which they expand states and in what they return.
"""
from __future__ import annotations

import heapq
import time as _time
from typing import Dict, List, Optional, Set, Tuple

from .constraints import CompiledConstraints, CutOff
from .instance import UNREACHABLE, MapfInstance
from .paths import Reservation
from .successors import (
    CLOCK_CHECK_MASK,
    FIELD_BITS,
    FIELD_MASK,
    SPREAD_SHIFT,
    Landmarks,
    cut_off,
    forever_h,
    goal_successors,
    horizon,
    key_shift,
    landmarks,
    make_successors,
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


def _goal_search_start(inst: MapfInstance, agent: int,
                       cc: CompiledConstraints) -> Optional[Tuple[int, int, Optional[Landmarks]]]:
    """``(h_start, floor, marks)`` of a search for ``agent``'s goal under ``cc``, or ``None`` where
    the start state already proves that no path exists.

    ``floor`` and ``marks`` are the :func:`~agents.search.mapf.successors.time_aware_h` arguments
    of the search (the final arrival later than ``goal_min``, the landmarks of ``cc``);
    ``h_start`` is the start's heuristic raised by them.
    """
    if cc.impossible:
        return None
    s = inst.starts[agent]
    hs = inst.h[agent][s]
    if hs >= UNREACHABLE:
        return None
    if inst.unit and s in cc.vset:
        return None
    floor = cc.goal_min + 1
    marks = landmarks(inst, agent, cc) if cc.ranges else None
    return time_aware_h(s, 0, hs, floor, marks), floor, marks


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

    Open entries are the packed successor keys ``f | conflicts | h | code`` of
    :func:`~agents.search.mapf.successors.make_successors`: the heap compares plain integers in
    the order of ``(f, conflicts, h, code)``.
    """
    counter.calls += 1
    start = _goal_search_start(inst, agent, cc)
    if start is None:
        return None
    hs, floor, marks = start
    if hs > cc.deadline:
        return None
    N = inst.n_nodes
    s, g = inst.starts[agent], inst.goals[agent]
    L = horizon(cc, res)
    # unit time: from the time every "never again" constraint holds on, the agent moves in the
    # graph without those nodes: its distances there are a stronger admissible heuristic, and
    # infinite where the goal is cut off (which proves infeasibility without sweeping the whole
    # horizon)
    closing = forever_h(inst, agent, cc) if inst.unit else None
    if closing is not None and closing[2][s] < 0:
        return None
    goal_min = cc.goal_min
    fb, fmask, clock = FIELD_BITS, FIELD_MASK, CLOCK_CHECK_MASK
    S1 = key_shift(L, N)  # shift of the heuristic field
    MASK = (1 << S1) - 1
    S2 = S1 + fb  # shift of the conflict-count field
    S3 = S2 + fb  # shift of f
    heap = [(hs << S3) | (hs << S1) | s]
    best = {s: hs << fb}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    successors = make_successors(inst, cc, res, inst.h[agent], tclose, L, floor=floor, marks=marks,
                                 closing=closing, f_limit=cc.deadline, successors_h=goal_successors(inst, agent),
                                 best=best, parent=parent, heap=heap)
    pops = 0
    pop = heapq.heappop
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
        successors(code, v, t, c)  # pushed onto the heap
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
    start = _goal_search_start(inst, agent, cc)
    if start is None:
        return None
    hs, floor, marks = start
    N = inst.n_nodes
    s, g = inst.starts[agent], inst.goals[agent]
    goal_min = cc.goal_min
    L = horizon(cc, res)
    fb, clock = FIELD_BITS, CLOCK_CHECK_MASK
    pop, push = heapq.heappop, heapq.heappush
    best = {s: hs << fb}
    parent = {s: -1}
    tclose: Dict[int, int] = {}
    successors = make_successors(inst, cc, res, inst.h[agent], tclose, L, floor=floor, marks=marks,
                                 successors_h=goal_successors(inst, agent), best=best, parent=parent)
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
        for ncode, nf, nc, hx in successors(code, v, t, c):
            push(open_f, (nf, ncode))
            if nf <= bound:
                push(focal, (nc >> sh, nf, nc & pm, hx - nf, ncode, hx))
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
    """Earliest time ``agent`` can be at ``target`` under ``cc`` without entering ``blocked``.

    Returns ``UNREACHABLE`` if it never can. Used to size corridor constraints. Open entries
    are the packed successor keys of :func:`~agents.search.mapf.successors.make_successors`
    (no conflicts counted): the heap compares plain integers in the order of ``(f, h, code)``.
    """
    N = inst.n_nodes
    hd = inst.dist_to(target, blocked)
    s = inst.starts[agent]
    if hd[s] >= UNREACHABLE:
        return UNREACHABLE
    if s == target:
        return 0
    L = cc.t_static + 1
    closing: Optional[CutOff] = None
    if inst.unit:
        # "never again" cut-offs of the nodes the search may enter
        closes = {x: fw for x, fw in cc.forever.items() if x != target and x not in blocked}
        if closes:
            cache = cc.cut_offs
            if cache is None:
                cache = cc.cut_offs = {}
            cut_key = (target, blocked)
            closing = cache.get(cut_key)
            if closing is None:
                closing = cache[cut_key] = cut_off(inst, target, blocked, closes)
            if closing[2][s] < 0:
                return UNREACHABLE
    if target in blocked:
        # ``hd`` keeps blocked nodes out but for the target itself: it is never entered either
        hd = list(hd)
        hd[target] = UNREACHABLE
    fmask, clock = FIELD_MASK, CLOCK_CHECK_MASK
    S1 = key_shift(L, N)  # shift of the heuristic field
    MASK = (1 << S1) - 1
    S3 = S1 + 2 * FIELD_BITS  # shift of f
    heap = [(hd[s] << S3) | (hd[s] << S1) | s]
    closed: Set[int] = set()
    successors = make_successors(inst, cc, None, hd, closed, L, closing=closing, heap=heap)
    pops = 0
    pop = heapq.heappop
    while heap:
        key = pop(heap)
        code = key & MASK
        if code in closed:
            continue
        closed.add(code)
        v = code % N
        t = (key >> S3) - ((key >> S1) & fmask)
        if v == target:
            counter.expanded += pops
            return t
        pops += 1
        if not pops & clock and _time.perf_counter() > deadline:
            counter.expanded += pops
            raise SearchTimeout
        successors(code, v, t, 0)  # pushed onto the heap
    counter.expanded += pops
    return UNREACHABLE
