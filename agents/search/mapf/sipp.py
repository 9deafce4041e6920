"""Safe-interval path planning (SIPP) against a table of other agents' timed paths.

Prioritised planning plans agents one after another; each later agent must avoid the timed
paths of the earlier ones. :class:`IntervalTable` records what those paths occupy, node by
node, as blocked integer ranges (with the nodes near them under proximity), and
:func:`sipp` finds one agent's earliest arrival at its goal that avoids them. SIPP searches
over ``(node, safe interval)`` states instead of ``(node, time)``: a node's safe intervals are
the maximal ranges in which nothing blocks it, and within one interval arriving earlier is
never worse (the agent can wait), so one state per interval suffices and the search stays
the size of the graph however long the horizon.

Occupancy follows :mod:`agents.search.mapf.paths` and :func:`~agents.search.mapf.validate.validate`:

- durative: during step ``[k, k + 1)`` an agent occupies the node it waits at, or both ends of
  the edge it traverses; a move ``u -> v`` of duration ``d`` leaving at ``t`` needs ``u`` free
  during ``t .. t + d - 1`` and ``v`` free during ``t .. t + d`` (it is at ``v`` at ``t + d``);
- unit: an agent occupies its node at each integer time, and two agents may not swap along an
  edge; a move leaving ``u`` at ``t`` needs ``v`` free at ``t + 1``.

In both an agent parks at its goal forever from its final arrival, so an arrival counts only
in a safe interval of the goal that never ends.
"""
from __future__ import annotations

import heapq
from bisect import bisect_right
from typing import Dict, Generic, List, Optional, Sequence, Set, Tuple, TypeVar, Union

import numpy as np

from . import compiled
from .instance import UNREACHABLE, MapfInstance

#: What a :class:`NodeRanges` caches per node.
C = TypeVar("C")

#: The end of an interval that never ends.
FOREVER = 1 << 50

#: The safe intervals of a node nothing blocks (shared: compared by identity in the search).
ALWAYS: List[Tuple[int, int]] = [(0, FOREVER)]
_ALWAYS_STARTS = [0]

#: A timed path ``[(node, time), ...]`` (the format of :class:`~agents.search.mapf.result.CBSResult`).
Events = List[Tuple[int, int]]


class NodeRanges(Generic[C]):
    """Time ranges per node, tagged with the agent they are kept for, recorded at the node and at
    the nodes near it, with a per-node cache (of safe intervals, or of segments) that a change
    clears. The shared bookkeeping of :class:`IntervalTable` and
    :class:`~agents.search.mapf.conflict_table.ConflictTable`.

    Args:
        inst: the instance (graph, time model, proximity).
    """

    def __init__(self, inst: MapfInstance) -> None:
        self.inst = inst
        self.unit = inst.unit
        n = inst.n_nodes
        #: per node, inclusive ranges ``(first, last, agent, is_hold)``
        self._ranges: List[List[Tuple[int, int, int, bool]]] = [[] for _ in range(n)]
        #: per node, what was computed from its ranges (``None``: to compute again)
        self._cache: List[Optional[C]] = [None] * n
        #: per agent, the nodes whose reach its path or hold blocks
        self._touched: Dict[Tuple[int, bool], Set[int]] = {}
        near = inst.near
        self._reach: List[Tuple[int, ...]] = [
            tuple([u] + near[u]) if near is not None else (u,) for u in range(n)]
        #: per node, its moves ``(v, duration)`` (waiting left out)
        self.out: List[List[Tuple[int, int]]] = [row[1:] for row in inst.succ_d]

    def _block(self, agent: int, hold: bool, node: int, first: int, last: int) -> None:
        self._touched.setdefault((agent, hold), set()).add(node)
        entry = (first, last, agent, hold)
        for x in self._reach[node]:
            self._ranges[x].append(entry)
            self._cache[x] = None

    def _drop(self, agent: int, hold: bool) -> None:
        for node in self._touched.pop((agent, hold), ()):
            for x in self._reach[node]:
                self._ranges[x] = [e for e in self._ranges[x] if e[2] != agent or e[3] != hold]
                self._cache[x] = None

    def hold(self, agent: int, node: int, last: int) -> None:
        """Keep ``node`` (and the nodes near it) for ``agent`` during ``0 .. last`` until
        :meth:`release` (an agent not planned yet waits at its start)."""
        self._block(agent, True, node, 0, last)

    def release(self, agent: int) -> None:
        """Drop what :meth:`hold` kept for ``agent``."""
        self._drop(agent, True)


class IntervalTable(NodeRanges[List[Tuple[int, int]]]):
    """Blocked time ranges per node (other agents and the nodes near them), and safe intervals.

    Every range is tagged with the agent it is kept for, so that a hold on an agent's start can
    be dropped once the agent is planned (:meth:`release`).

    Args:
        inst: the instance (graph, time model, proximity).
    """

    def __init__(self, inst: MapfInstance) -> None:
        super().__init__(inst)
        n = inst.n_nodes
        self._starts: List[Optional[List[int]]] = [None] * n
        #: unit time: reserved moves ``(u, v, t)`` (leaving ``u`` at ``t``), for swap checks
        self.moves: Set[Tuple[int, int, int]] = set()

    def holders(self, node: int) -> Set[int]:
        """The agents not planned yet whose held start blocks ``node``."""
        return {e[2] for e in self._ranges[node] if e[3]}

    def reserve(self, agent: int, events: Sequence[Tuple[int, int]]) -> None:
        """Block what ``agent`` following ``events`` (then parked at its last node) occupies."""
        unit = self.unit
        for (u, t0), (v, t1) in zip(events, events[1:]):
            self._block(agent, False, u, t0, t1 - 1)
            if u != v:
                if unit:
                    self.moves.add((u, v, t0))
                else:
                    self._block(agent, False, v, t0, t1 - 1)
        g, t_end = events[-1]
        self._block(agent, False, g, t_end, FOREVER)

    def safe(self, node: int) -> List[Tuple[int, int]]:
        """The safe intervals of ``node``: sorted disjoint inclusive ranges ``(first, last)``."""
        s = self._cache[node]
        if s is None:
            if not self._ranges[node]:
                self._cache[node] = ALWAYS
                self._starts[node] = _ALWAYS_STARTS
                return ALWAYS
            s = []
            nxt = 0
            for a, b, _, _ in sorted(self._ranges[node]):
                if a > nxt:
                    s.append((nxt, a - 1))
                if b + 1 > nxt:
                    nxt = b + 1
            if nxt <= FOREVER:
                s.append((nxt, FOREVER))
            self._cache[node] = s
            self._starts[node] = [a for a, _ in s]
        return s


class ArrayIntervalTable:
    """:class:`IntervalTable` with its ranges and safe intervals in arrays, kept by compiled loops
    (:mod:`~agents.search.mapf.compiled`): what the array form of :func:`sipp` reads, with no
    Python work per blocked node. Durative time only; the same interface and the same safe
    intervals as :class:`IntervalTable` (make either with :func:`interval_table`).

    Each blocked range is an entry ``(first, last, agent, is_hold)`` in a linked list per node
    (recorded at the node and at the nodes near it); a change flags the nodes it touched, and
    :meth:`arrays` recomputes their safe intervals.

    Args:
        inst: the instance (graph, durative time model, proximity).
        capacity: room for this many entries at first (the arrays grow as needed).
        intervals: room for this many safe intervals per node at first (likewise).
    """

    def __init__(self, inst: MapfInstance, capacity: int = 1024, intervals: int = 4) -> None:
        if inst.unit:
            raise ValueError("ArrayIntervalTable keeps durative time only; use IntervalTable")
        self.inst = inst
        self.unit = False
        n = inst.n_nodes
        self.reach_ptr, self.reach_idx = _reach_csr(inst)
        self.head = np.full(n, -1, dtype=np.int64)
        self.top = 0
        self.e_first = np.zeros(0, dtype=np.int64)
        self.e_last = np.zeros(0, dtype=np.int64)
        self.e_agent = np.zeros(0, dtype=np.int64)
        self.e_hold = np.zeros(0, dtype=np.uint8)
        self.e_next = np.zeros(0, dtype=np.int64)
        self._grow_entries(capacity)
        self.dirty = np.ones(n, dtype=np.uint8)  # every node's intervals still to compute
        self.dirty_list = np.arange(n, dtype=np.int64)
        self.n_dirty = n
        self.search = _SearchArrays(n, intervals)
        #: per agent, the nodes it holds
        self._held: Dict[int, Set[int]] = {}
        self._max_reach = int(np.diff(self.reach_ptr).max()) if n else 0

    def _grow_entries(self, need: int) -> None:
        cap = max(need, 2 * len(self.e_next))
        for name in ("e_first", "e_last", "e_agent", "e_hold", "e_next"):
            old = getattr(self, name)
            new = np.zeros(cap, dtype=old.dtype)
            new[:self.top] = old[:self.top]
            setattr(self, name, new)

    def _block(self, events: np.ndarray, agent: int, hold: bool) -> None:
        need = self.top + 2 * len(events) * self._max_reach
        if need > len(self.e_next):
            self._grow_entries(need)
        self.top, self.n_dirty = compiled.block_ranges(
            events, FOREVER, agent, int(hold), self.reach_ptr, self.reach_idx, self.head, self.e_first, self.e_last,
            self.e_agent, self.e_hold, self.e_next, self.top, self.dirty, self.dirty_list, self.n_dirty)

    def hold(self, agent: int, node: int, last: int) -> None:
        """As :meth:`IntervalTable.hold`."""
        self._held.setdefault(agent, set()).add(node)
        self._block(np.array([[node, last]], dtype=np.int64), agent, True)

    def release(self, agent: int) -> None:
        """As :meth:`IntervalTable.release`."""
        for node in self._held.pop(agent, ()):
            self.n_dirty = compiled.drop_holds(node, agent, self.reach_ptr, self.reach_idx, self.head, self.e_agent,
                                               self.e_hold, self.e_next, self.dirty, self.dirty_list, self.n_dirty)

    def reserve(self, agent: int, events: Sequence[Tuple[int, int]]) -> None:
        """As :meth:`IntervalTable.reserve`."""
        self._block(np.asarray(events, dtype=np.int64).reshape(-1, 2), agent, False)

    def holders(self, node: int) -> Set[int]:
        """As :meth:`IntervalTable.holders`."""
        out = set()
        e = int(self.head[node])
        while e >= 0:
            if self.e_hold[e]:
                out.add(int(self.e_agent[e]))
            e = int(self.e_next[e])
        return out

    def safe(self, node: int) -> List[Tuple[int, int]]:
        """As :meth:`IntervalTable.safe`."""
        arr = self.arrays()
        return [(int(arr.lo[node, j]), int(arr.hi[node, j])) for j in range(int(arr.n[node]))]

    def arrays(self) -> "_SearchArrays":
        """The safe intervals of every node as arrays (brought up to date), with the compiled
        search's scratch space."""
        arr = self.search
        done = 0
        while done < self.n_dirty:
            done, need = compiled.refresh_intervals(self.dirty_list, done, self.n_dirty, self.dirty, self.head,
                                                    self.e_first, self.e_last, self.e_next, arr.lo, arr.hi, arr.n,
                                                    FOREVER)
            if need:
                arr.grow(need)
        self.n_dirty = 0
        return arr


def _reach_csr(inst: MapfInstance) -> Tuple[np.ndarray, np.ndarray]:
    """Per node, itself and the nodes near it, as CSR arrays ``(indptr, nodes)``."""
    n, near = inst.n_nodes, inst.near
    if near is None:
        return np.arange(n + 1, dtype=np.int64), np.arange(n, dtype=np.int64)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([1 + len(x) for x in near], out=indptr[1:])
    nodes = np.fromiter((v for u in range(n) for v in (u, *near[u])), dtype=np.int64, count=int(indptr[-1]))
    return indptr, nodes


def interval_table(inst: MapfInstance) -> Union[IntervalTable, ArrayIntervalTable]:
    """The table :func:`sipp` searches fastest against on ``inst``: :class:`ArrayIntervalTable`
    under durative time where the compiled loops are active, :class:`IntervalTable` otherwise."""
    if not inst.unit and compiled.active():
        return ArrayIntervalTable(inst)
    return IntervalTable(inst)


class _SearchArrays:
    """Safe intervals per node (``lo[v, j]``, ``hi[v, j]`` for ``j < n[v]``) and the scratch space
    of one compiled safe-interval search over ``(node, interval)`` codes (``j * N + v``)."""

    def __init__(self, n_nodes: int, cap: int = 4) -> None:
        self.n_nodes = n_nodes
        self.cap = 0
        self.lo = np.zeros((n_nodes, 0), dtype=np.int64)
        self.hi = np.zeros((n_nodes, 0), dtype=np.int64)
        self.n = np.zeros(n_nodes, dtype=np.int64)
        self.expl = np.zeros(n_nodes, dtype=np.uint8)
        self.grow(cap)

    def grow(self, need: int) -> None:
        """Room for at least ``need`` intervals per node."""
        cap = max(need, 2 * self.cap)
        lo = np.zeros((self.n_nodes, cap), dtype=np.int64)
        hi = np.zeros((self.n_nodes, cap), dtype=np.int64)
        lo[:, :self.cap] = self.lo
        hi[:, :self.cap] = self.hi
        self.lo, self.hi, self.cap = lo, hi, cap
        size = self.n_nodes * cap
        self.best = np.full(size, FOREVER, dtype=np.int64)
        self.par_code = np.zeros(size, dtype=np.int64)
        self.par_t = np.zeros(size, dtype=np.int64)
        self.touched = np.zeros(size, dtype=np.int64)


def _sipp_compiled(inst: MapfInstance, agent: int, table: ArrayIntervalTable, budget: Optional[int],
                   count: List[int], explored: Optional[Set[int]]) -> Optional[Events]:
    """:func:`sipp` against an :class:`ArrayIntervalTable` by the compiled loop (the same path, the
    same expansions)."""
    arr = table.arrays()
    s = inst.starts[agent]
    if arr.n[s] == 0 or arr.lo[s, 0] != 0:
        return None  # the start is blocked at time 0
    indptr, targets, durs = inst.moves_csr
    h = inst.h_array[agent]
    arr.expl.fill(0)
    status, code, done, nt = compiled.sipp_durative(
        inst.starts[agent], inst.goals[agent], h, indptr, targets, durs, arr.lo, arr.hi, arr.n, arr.best,
        arr.par_code, arr.par_t, arr.touched, arr.expl, count[0], -1 if budget is None else int(budget),
        FOREVER, UNREACHABLE)
    count[0] = int(done)
    try:
        if explored is not None:
            explored.update(np.flatnonzero(arr.expl).tolist())
        if status == compiled.OVER_BUDGET:
            raise BudgetExceeded
        if status != compiled.FOUND:
            return None
        N = inst.n_nodes
        best, par_code, par_t = arr.best, arr.par_code, arr.par_t
        code = int(code)
        out: Events = [(code % N, int(best[code]))]
        while par_code[code] >= 0:
            prev, t_dep = int(par_code[code]), int(par_t[code])
            t_prev = int(best[prev])
            if t_dep > t_prev:
                out.append((prev % N, t_dep))
            out.append((prev % N, t_prev))
            code = prev
        out.reverse()
        return out
    finally:
        arr.best[arr.touched[:nt]] = FOREVER


class BudgetExceeded(Exception):
    """Raised by :func:`sipp` when its expansion budget runs out."""


def sipp(inst: MapfInstance, agent: int, table: Union[IntervalTable, ArrayIntervalTable], budget: Optional[int] = None,
         counter: Optional[List[int]] = None, explored: Optional[Set[int]] = None) -> Optional[Events]:
    """The earliest timed path of ``agent`` to its goal that avoids ``table`` (``None``: none).

    A* over ``(node, safe interval)`` states with the instance's true-distance heuristic; ties
    go to the deeper state. ``counter`` (a one-element list) accumulates expansions; once it
    exceeds ``budget`` the search raises :class:`BudgetExceeded`. ``explored`` (optional)
    collects the nodes the search expanded (where a search that fails was confined). The path is optimal: it
    arrives at the goal no later than any other path that avoids the table and parks there.

    Against an :class:`ArrayIntervalTable` (durative time, see :func:`interval_table`) the search
    runs as a compiled loop (:mod:`~agents.search.mapf.compiled`) over the table's intervals as
    arrays: the same states in the same order, so the same path and the same expansions.
    """
    s, g = inst.starts[agent], inst.goals[agent]
    if inst.h_array[agent, s] >= UNREACHABLE:
        return None
    count = counter if counter is not None else [0]
    if isinstance(table, ArrayIntervalTable):
        return _sipp_compiled(inst, agent, table, budget, count, explored)
    h = inst.h[agent]
    safe = table.safe
    cache = table._cache
    starts_cache = table._starts  # set together with ``cache`` by ``safe``
    unit = table.unit
    moves = table.moves
    out = table.out
    N = inst.n_nodes
    s_int = safe(s)
    if not s_int or s_int[0][0] != 0:
        return None  # the start is blocked at time 0
    push, pop = heapq.heappush, heapq.heappop
    # a state (node v, its j-th safe interval) is coded j * N + v; best arrival and parent per code
    best: Dict[int, int] = {s: 0}
    parent: Dict[int, Tuple[int, int]] = {}
    heap = [(h[s], 0, s)]
    while heap:
        f, neg_t, code = pop(heap)
        t_u = -neg_t
        if best[code] < t_u:
            continue
        u = code % N
        b_u = cache[u][code // N][1]  # type: ignore[index]
        if u == g and b_u == FOREVER:
            return _events(code, N, best, parent)
        count[0] += 1
        if explored is not None:
            explored.add(u)
        if budget is not None and count[0] > budget:
            raise BudgetExceeded
        for v, d in out[u]:
            hv = h[v]
            if hv >= UNREACHABLE:
                continue
            t_hi = b_u - d + 1  # leave by then: u stays free while leaving
            if t_hi < t_u:
                continue
            v_int = cache[v]
            if v_int is None:
                v_int = safe(v)
            if v_int is ALWAYS and not unit:  # the common case: nothing ever blocks v
                arr = t_u + d
                if arr < best.get(v, FOREVER):
                    best[v] = arr
                    parent[v] = (code, t_u)
                    push(heap, (arr + hv, -arr, v))
                continue
            lead = d if unit else 0  # v must be free from t + lead to t + d
            # first interval of v that could contain t + lead for some t >= t_u
            n_int = len(v_int)
            if n_int == 1:
                j = 0
            else:
                j = bisect_right(starts_cache[v], t_u + lead) - 1  # type: ignore[arg-type]
                if j < 0:
                    j = 0
            for jv in range(j, n_int):
                a_v, b_v = v_int[jv]
                if a_v - lead > t_hi:
                    break
                t = t_u if t_u > a_v - lead else a_v - lead
                last = t_hi if t_hi < b_v - d else b_v - d
                if unit:
                    while t <= last and (v, u, t) in moves:
                        t += 1
                if t > last:
                    continue
                arr = t + d
                key = jv * N + v
                if arr < best.get(key, FOREVER):
                    best[key] = arr
                    parent[key] = (code, t)
                    push(heap, (arr + hv, -arr, key))
    return None


def _events(code: int, N: int, best: Dict[int, int], parent: Dict[int, Tuple[int, int]]) -> Events:
    """Rebuild ``[(node, time), ...]``: each arrival, and the departure after a wait."""
    out: Events = [(code % N, best[code])]
    while code in parent:
        prev, t_dep = parent[code]
        if t_dep > best[prev]:
            out.append((prev % N, t_dep))
        out.append((prev % N, best[prev]))
        code = prev
    out.reverse()
    return out
