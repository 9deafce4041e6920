"""What the low-level searches share: successor generation, time-aware heuristics, packing constants.

The low-level searches (:mod:`agents.search.mapf.lowlevel`, and the MDDs of
:mod:`agents.search.mapf.mdd`) expand states ``(node, time)``, encoded as integers
``time * N + node``. This module holds the pieces they have in common:

- :func:`make_successors`: the successor function of one search, under both time models: the
  moves an agent's compiled constraints allow from a state (waits included), their conflicts
  with a :class:`~agents.search.mapf.paths.Reservation`, their heuristic, and the search's own
  rules (closed states, a bound on ``f``, keeping only improvements, pushing onto a heap);
- :func:`time_aware_h`: the heuristic of a state raised to what the constraints prove (a final
  arrival later than ``goal_min``, and the landmark bounds of finite range constraints); the
  searches apply it to their start state, :func:`make_successors` to each successor;
- :func:`horizon`, :func:`landmarks`, :func:`forever_h`, :func:`cut_off`,
  :func:`goal_successors`: tables the searches build once per call (cached where they depend
  only on the constraints or the instance);
- the bit fields the searches pack their priorities into (:data:`FIELD_BITS`, :func:`key_shift`).
"""
from __future__ import annotations

import heapq
from typing import Callable, Container, Dict, List, Optional, Set, Tuple

from .constraints import CompiledConstraints, CutOff
from .instance import UNREACHABLE, MapfInstance
from .paths import Reservation

#: Width of the conflict-count field of a packed priority ``(f << FIELD_BITS) | conflicts``
#: (the ``best`` tables of the searches), and of the conflict-count and heuristic fields of the
#: successor keys ``f | conflicts | h | code`` (see :func:`make_successors`). Conflict counts and
#: heuristic values stay far below ``2 ** FIELD_BITS``; comparing two packed integers compares
#: ``(f, conflicts)``.
FIELD_BITS = 24
#: Mask of one :data:`FIELD_BITS` wide field.
FIELD_MASK = (1 << FIELD_BITS) - 1
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

#: No limit on a successor's ``f`` (see :func:`make_successors`).
NO_LIMIT = 1 << 62

#: ``successors(code, v, t, c) -> [(code, f, conflicts, h), ...]`` (see :func:`make_successors`)
Successors = Callable[[int, int, int, int], List[Tuple[int, int, int, int]]]
#: node -> ``[(start, end, bound), ...]`` (see :func:`landmarks`)
Landmarks = Dict[int, List[Tuple[int, int, int]]]


def key_shift(horizon_time: int, n_nodes: int) -> int:
    """Shift of the heuristic field of a successor key (see :func:`make_successors`): the code
    field below it holds the codes below ``(horizon_time + 1) * n_nodes``."""
    return ((horizon_time + 1) * n_nodes).bit_length()


def make_successors(inst: MapfInstance, cc: CompiledConstraints, res: Optional[Reservation], h: List[int],
                    closed: Container[int], horizon_time: int, *, floor: int = 0,
                    marks: Optional[Landmarks] = None, closing: Optional[CutOff] = None, f_limit: int = NO_LIMIT,
                    successors_h: Optional[List[List[Tuple[int, int]]]] = None,
                    best: Optional[Dict[int, int]] = None, parent: Optional[Dict[int, int]] = None,
                    heap: Optional[List[int]] = None) -> Successors:
    """``successors(code, v, t, c)``: the successors of the state ``code`` (node ``v`` at time
    ``t``, reached with ``c`` conflicts) in one agent's search, the wait first, then the moves in
    the graph's order, as a list of ``(code, f, conflicts, h)``.

    ``f`` is the arrival plus ``h``; ``conflicts`` is ``c`` plus the move's conflicts with
    ``res``. Built once per search, the function holds every check a move must pass (the
    constraints, the reachability of the target, the search's closed states and bound), so that
    the searches differ only in the order in which they expand states. With ``heap``, each
    successor is pushed onto it instead as the single integer ``f | conflicts | h | code`` (bit
    fields, most significant first: the conflict and heuristic fields :data:`FIELD_BITS` wide,
    the code field :func:`key_shift` bits), which compares as the tuple ``(f, conflicts, h, code)``.

    Args:
        inst: the instance; its time model decides what a move occupies and when it arrives.
        cc: the agent's compiled constraints; a move they forbid is left out.
        res: the other agents' paths, whose conflicts with each move are counted (spreading
            routes: see :data:`SPREAD_SHIFT`); ``None``: none are counted.
        h: distance of every node to the search's target; a move to a node where it is
            :data:`UNREACHABLE` is left out.
        closed: the codes of the states the search has closed; a move to one is left out.
        horizon_time: a move arriving at ``w`` at time ``nt`` has the code
            ``min(nt, horizon_time) * N + w`` (see :func:`horizon`).
        floor, marks: a successor's ``h`` is ``h[w]`` raised by :func:`time_aware_h` with these
            (the final arrival later than ``goal_min``, the landmarks of ``cc``).
        closing: unit time, ``(TF, hF, late)`` of the nodes that close for good (:func:`cut_off`):
            a move later than ``late`` is left out; from ``TF`` on a successor's ``h`` is ``hF``.
        f_limit: a successor with a larger ``f`` is left out.
        successors_h: unit time, per node, ``(successor, h[successor])`` where ``h`` is finite
            (:func:`goal_successors`); built node by node where not given.
        best, parent: the search's best ``(f << FIELD_BITS) | conflicts`` and parent per code:
            where given, only successors that improve on ``best`` are kept, and recorded in both.
        heap: the search's open list, where the successors are pushed (the list returned stays
            empty); ``None``: they are returned.
    """
    N = inst.n_nodes
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    counting = res is not None
    occ, moves, parked = (res.occ, res.moves, res.parked) if res is not None else EMPTY_RESERVATION
    L = horizon_time
    raising = floor > 0 or marks is not None  # else time_aware_h raises nothing (every f is >= 1)
    relax = best is not None
    bests: Dict[int, int] = best if best is not None else {}
    parents: Dict[int, int] = parent if parent is not None else {}
    pushing = heap is not None
    open_keys: List[int] = heap if heap is not None else []
    push = heapq.heappush
    fb = FIELD_BITS
    S1 = key_shift(L, N)
    S2 = S1 + fb
    S3 = S2 + fb
    if inst.unit:
        NN = N * N
        LN = L * N
        succ = inst.succ
        TF, hF, late = closing if closing is not None else (NEVER, [], None)
        table: List[Optional[List[Tuple[int, int]]]] = (
            [None] * N if successors_h is None else successors_h)  # type: ignore[assignment]

        def successors(code: int, v: int, t: int, c: int) -> List[Tuple[int, int, int, int]]:
            nt = t + 1
            vbase = nt * N
            base = vbase if nt < L else LN
            tNN = t * NN
            src = tNN + v * N
            out = []
            ws = table[v]
            if ws is None:
                ws = table[v] = [(w, hw) for w in succ[v] if (hw := h[w]) < UNREACHABLE]
            for w, hw in ws:  # at w at time nt
                ncode = base + w
                if ncode in closed:
                    continue
                vc = vbase + w
                if vc in vset:
                    continue
                if eset and w != v and (src + w) in eset:
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
                nf = nt + hw
                if nf > f_limit:
                    continue
                if raising and (nf < floor or (marks is not None and w in marks)):
                    hw = time_aware_h(w, nt, hw, floor, marks)
                    nf = nt + hw
                    if nf > f_limit:
                        continue
                nc = c
                if counting:
                    if w != v and (tNN + w * N + v) in moves:
                        nc += 1
                    if vc in occ:
                        nc += 1
                    if parked:
                        pt = parked.get(w)
                        if pt is not None and nt >= pt:
                            nc += 1
                if relax:
                    pk = (nf << fb) | nc
                    old = bests.get(ncode)
                    if old is not None and old <= pk:
                        continue
                    bests[ncode] = pk
                    parents[ncode] = code
                if pushing:
                    push(open_keys, (nf << S3) | (nc << S2) | (hw << S1) | ncode)
                else:
                    out.append((ncode, nf, nc, hw))
            return out

        return successors

    succ_d = inst.succ_d
    places = res.places if res is not None else None

    def successors_durative(code: int, v: int, t: int, c: int) -> List[Tuple[int, int, int, int]]:
        out = []
        fv = forever.get(v) if forever else None
        pv = parked.get(v) if parked else None
        # staying on v during the steps t, t + 1, ... (a move occupies the node it leaves for its
        # whole duration) is allowed in the first v_steps of them, as far as looked at so far
        # (v_open: no step looked at forbids it), with v_conf[j] conflicts in the first j
        v_conf = [0]
        v_steps = 0
        v_open = True
        for w, d in succ_d[v]:  # occupying v and w during the steps t .. nt - 1, at w at time nt
            hw = h[w]
            if hw >= UNREACHABLE:
                continue
            nt = t + d
            nf = nt + hw
            if nf > f_limit:
                continue
            ncode = (nt if nt < L else L) * N + w
            if ncode in closed:
                continue
            last = nt - 1
            if fv is not None and last >= fv:
                continue
            if d > v_steps:
                if not v_open:
                    continue
                k = (t + v_steps) * N + v
                n = v_conf[v_steps]
                while v_steps < d:
                    if k in vset:
                        v_open = False
                        break
                    if k in occ:
                        n += 1
                    v_conf.append(n)
                    v_steps += 1
                    k += N
                if d > v_steps:
                    continue
            dc = v_conf[d]
            if w != v:
                if forever:
                    fw = forever.get(w)
                    if fw is not None and last >= fw:
                        continue
                k = t * N + w
                end = k + d * N
                while k < end:
                    if k in vset:
                        break
                    if k in occ:
                        dc += 1
                    k += N
                if k < end:
                    continue
                if parked:
                    pw = parked.get(w)
                    if pw is not None and last >= pw:
                        dc += 1
            if pv is not None and last >= pv:
                dc += 1
            if places:
                dc = (dc << SPREAD_SHIFT) + (0 if w == v or w not in places else 1)
            if raising and (nf < floor or (marks is not None and w in marks)):
                hw = time_aware_h(w, nt, hw, floor, marks)
                nf = nt + hw
                if nf > f_limit:
                    continue
            nc = c + dc
            if relax:
                pk = (nf << fb) | nc
                old = bests.get(ncode)
                if old is not None and old <= pk:
                    continue
                bests[ncode] = pk
                parents[ncode] = code
            if pushing:
                push(open_keys, (nf << S3) | (nc << S2) | (hw << S1) | ncode)
            else:
                out.append((ncode, nf, nc, hw))
        return out

    return successors_durative


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


def forever_h(inst: MapfInstance, agent: int, cc: CompiledConstraints) -> Optional[CutOff]:
    """Unit time: ``(TF, hF, late)`` for the "never again" constraints of ``cc`` (cached on ``cc``).

    From time ``TF`` on every such node is closed for good, and ``hF`` holds the distances to the
    goal avoiding them. ``late[v]`` is the last time at which being at ``v`` can still lead to the
    goal: from a node that reaches the goal only through a closed node ``x``, the last visit to
    such a node must come before it closes, so ``t + dist(v, x) <= fw(x) - 1`` for some ``x``.
    ``None`` without such constraints.
    """
    if not cc.forever:
        return None
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


def goal_successors(inst: MapfInstance, agent: int) -> Optional[List[List[Tuple[int, int]]]]:
    """Unit time: per node, ``(successor, its distance to the agent's goal)`` for the successors
    (wait first) from which the goal can be reached (cached on the instance); ``None`` under the
    durative model (its successor function reads the distances directly)."""
    if not inst.unit:
        return None
    cache = inst._goal_successors
    out = cache.get(agent)
    if out is None:
        h = inst.h[agent]
        out = [[(w, h[w]) for w in ws if h[w] < UNREACHABLE] for ws in inst.succ]
        cache[agent] = out
    return out
