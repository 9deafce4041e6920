"""What the low-level searches share: successor generation, time-aware heuristics, packing constants.

The low-level searches (:mod:`agents.search.mapf.lowlevel`) expand states ``(node, time)``,
encoded as integers ``time * N + node``. This module holds the pieces they have in common:

- :func:`make_expander`: the successors of a state under an agent's compiled constraints, with
  the number of conflicts each step has with a :class:`~agents.search.mapf.paths.Reservation`;
- :func:`time_aware_h`: the heuristic of a state raised to what the constraints prove (a final
  arrival later than ``goal_min``, and the landmark bounds of finite range constraints); every
  search applies it to its start state and to each successor;
- :func:`horizon`, :func:`landmarks`, :func:`forever_h`, :func:`cut_off`,
  :func:`goal_successors`: tables the searches build once per call (cached where they depend
  only on the constraints or the instance);
- the widths of the bit fields the searches pack their priorities into (:data:`FIELD_BITS`).
"""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Set, Tuple

from .constraints import CompiledConstraints, CutOff
from .instance import UNREACHABLE, MapfInstance
from .paths import Reservation

#: Width of the conflict-count field of a packed priority ``(f << FIELD_BITS) | conflicts``
#: (the ``best`` tables of the searches), and of the conflict-count and heuristic fields of the
#: unit-time A* heap keys ``f | conflicts | h | code``. Conflict counts and heuristic values stay
#: far below ``2 ** FIELD_BITS``; comparing two packed integers compares ``(f, conflicts)``.
FIELD_BITS = 24
#: Mask of one :data:`FIELD_BITS` wide field.
FIELD_MASK = (1 << FIELD_BITS) - 1
#: Radix of the heuristic in the keys of the unit-time earliest-arrival search
#: ``(f * H_RADIX + h) * M + code``: heuristic values stay below it.
H_RADIX = 1 << 30
#: The searches read the clock once every ``CLOCK_CHECK_MASK + 1`` expansions.
CLOCK_CHECK_MASK = (1 << 10) - 1
#: "Never": the time from which no "never again" constraint closes a node (there are none).
NEVER = 1 << 62

#: A reservation holding nothing: ``(occupied codes, move codes, parked node -> time)``.
EMPTY_RESERVATION: Tuple[Set[int], Set[int], Dict[int, int]] = (set(), set(), {})

#: With a reservation's ``places`` (spreading routes), a successor's tie-break value is its
#: conflicts shifted left by this many bits plus 1 where it enters one of those places:
#: conflicts still come first, and the searches compare the two parts separately (a path that
#: enters more than 255 such places would carry into the conflicts' part).
SPREAD_SHIFT = 8

#: ``expand(v, t) -> [(w, t_arrival, n_conflicts), ...]``
Expander = Callable[[int, int], List[Tuple[int, int, int]]]
#: node -> ``[(start, end, bound), ...]`` (see :func:`landmarks`)
Landmarks = Dict[int, List[Tuple[int, int, int]]]
#: ``(TF, hF, late)`` with ``hF`` and ``late`` ``None`` when no node ever closes (see :func:`forever_h`)
ForeverH = Tuple[int, Optional[List[int]], Optional[List[int]]]

_NO_FOREVER: ForeverH = (NEVER, None, None)


def make_expander(inst: MapfInstance, cc: CompiledConstraints, res: Optional[Reservation]) -> Expander:
    """``expand(v, t) -> [(w, t_arrival, n_conflicts), ...]`` under the constraints ``cc``.

    ``n_conflicts`` counts the successor's conflicts with the reservation ``res``; under the
    durative model, where ``res.places`` is not empty, it is that count times
    ``2 ** SPREAD_SHIFT`` (:data:`SPREAD_SHIFT`), plus 1 for a move into one of those places (routes
    spread apart).
    """
    N = inst.n_nodes
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else EMPTY_RESERVATION
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
    places = res.places if res is not None else None

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
            if places:
                dc = (dc << SPREAD_SHIFT) + (0 if same or w not in places else 1)
            out.append((w, nt, dc))
        return out

    return expand_d


def time_aware_h(v: int, t: int, h: int, floor: int, marks: Optional[Landmarks]) -> int:
    """The heuristic ``h`` of being at node ``v`` at time ``t``, raised to what the constraints prove.

    The final arrival is at least ``floor`` (``goal_min + 1``), and at least the ``bound`` of
    every landmark entry ``(start, end, bound)`` of ``v`` whose window holds ``t`` (see
    :func:`landmarks`). Returns the remaining time, at least ``h``. The searches call it for the
    start state and, for a successor, only where it can change something
    (``t + h < floor`` or ``v`` has landmark entries), which keeps their inner loops fast.
    """
    if t + h < floor:
        h = floor - t
    if marks is not None:
        for lo, hi, bound in marks.get(v, ()):
            if lo <= t <= hi and t + h < bound:
                h = bound - t
    return h


def horizon(cc: CompiledConstraints, res: Optional[Reservation]) -> int:
    """After this time, states at the same node are interchangeable (nothing changes anymore)."""
    h = cc.t_static
    if res is not None and res.horizon > h:
        h = res.horizon
    return h + 1


def landmarks(inst: MapfInstance, agent: int, cc: CompiledConstraints) -> Landmarks:
    """For finite range constraints on a node B: node -> [(start, end, bound)] for the nodes whose
    every path to the goal crosses B; from such a node at a time in [start, end] the final
    arrival is at least ``bound = end + 1 + h(B)`` (B is closed until ``end``). Cached on ``cc``."""
    lm = cc.landmarks
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
        cc.landmarks = lm
    return lm


def forever_h(inst: MapfInstance, agent: int, cc: CompiledConstraints) -> ForeverH:
    """Unit time: ``(TF, hF, late)`` for the "never again" constraints of ``cc`` (cached on ``cc``).

    From time ``TF`` on every such node is closed for good, and ``hF`` holds the distances to the
    goal avoiding them. ``late[v]`` is the last time at which being at ``v`` can still lead to the
    goal: from a node that reaches the goal only through a closed node ``x``, the last visit to
    such a node must come before it closes, so ``t + dist(v, x) <= fw(x) - 1`` for some ``x``.
    Without such constraints: ``(NEVER, None, None)``.
    """
    if not cc.forever:
        return _NO_FOREVER
    out = cc.forever_h
    if out is None:
        out = cc.forever_h = cut_off(inst, inst.goals[agent], frozenset(), cc.forever)
    return out


def cut_off(inst: MapfInstance, target: int, blocked: frozenset, closing: Dict[int, int]) -> CutOff:
    """``(TF, hF, late)`` for reaching ``target`` avoiding ``blocked`` when each node ``x`` of
    ``closing`` is closed for good from time ``closing[x]`` (unit time; see :func:`forever_h`)."""
    hF = inst.dist_to(target, blocked | frozenset(closing))
    late = [UNREACHABLE] * inst.n_nodes
    cut = [v for v in range(inst.n_nodes) if hF[v] >= UNREACHABLE]
    if cut:
        to_x = [(fw - 1, inst.dist_to(x)) for x, fw in closing.items()]
        for v in cut:
            late[v] = max(lim - d[v] for lim, d in to_x)
    return max(closing.values()), hF, late


def goal_successors(inst: MapfInstance, agent: int) -> List[List[Tuple[int, int]]]:
    """Per node, ``(successor, its distance to the agent's goal)`` for the successors (wait first)
    from which the goal can be reached (cached on the instance)."""
    cache = inst._goal_successors
    out = cache.get(agent)
    if out is None:
        h = inst.h[agent]
        out = [[(w, h[w]) for w in ws if h[w] < UNREACHABLE] for ws in inst.succ]
        cache[agent] = out
    return out
