"""Compiled inner loops of the solvers, where numba is installed (optional).

numba is not a dependency: without it, or with ``ENABLED`` set to ``False``, every solver runs
its pure-Python loop. The compiled loops give the same results as the Python ones (the same
states, in the same order, with the same tie-breaks) and count the same work against the same
budgets; only the time differs.

- :func:`sipp_durative`: the safe-interval search of :func:`~agents.search.mapf.sipp.sipp`
  under the durative time model (about 20 times faster on a 6000-node buffer graph);
- :func:`reaches`: whether a node reaches another through open nodes, the test of
  :func:`~agents.search.mapf.prioritized.release_order`;
- :func:`block_ranges`, :func:`drop_holds`, :func:`refresh_intervals`: the bookkeeping of
  :class:`~agents.search.mapf.sipp.ArrayIntervalTable` (blocked time ranges per node in linked
  lists of entries, and the safe intervals of the nodes they changed).
"""
from __future__ import annotations

import heapq
import os
from typing import Any, Tuple

import numpy as np

_numba: Any
try:  # pragma: no cover - depends on the environment
    import numba as _numba
except ImportError:  # pragma: no cover - depends on the environment
    _numba = None

#: numba is importable
AVAILABLE = _numba is not None
#: the solvers use the compiled loops (where numba is installed; the environment variable
#: ``SAFE_MAPF_COMPILED=0`` turns them off, and so does setting this to ``False``)
ENABLED = AVAILABLE and os.environ.get("SAFE_MAPF_COMPILED", "1") != "0"

#: what :func:`sipp_durative` reports
FOUND, NO_PATH, OVER_BUDGET = 0, 1, 2


def active() -> bool:
    """Whether the solvers use the compiled loops now."""
    return AVAILABLE and ENABLED


def _sipp_durative_py(s: int, g: int, h: np.ndarray, indptr: np.ndarray, indices: np.ndarray, durs: np.ndarray,
                      iv_lo: np.ndarray, iv_hi: np.ndarray, iv_n: np.ndarray, best: np.ndarray,
                      par_code: np.ndarray, par_t: np.ndarray, touched: np.ndarray, expl: np.ndarray,
                      count: int, budget: int, forever: int, unreachable: int) -> Tuple[int, int, int, int]:
    """A* over ``(node, safe interval)`` states, durative time (see :func:`~agents.search.mapf.sipp.sipp`).

    A state (node ``v``, its ``j``-th safe interval) is coded ``j * N + v``; ``best``, ``par_code``
    and ``par_t`` (size ``N * cap``) hold its earliest arrival, its parent's code and the departure
    from the parent, ``FOREVER`` in ``best`` where not reached (the codes set are listed in
    ``touched``, for the caller to reset). ``iv_lo[v, j]``, ``iv_hi[v, j]`` (``j < iv_n[v]``) are
    the safe intervals of ``v``. ``expl[u]`` is set for every node expanded. ``count`` is the
    expansions so far; past ``budget`` (``-1``: none) the search stops.

    Returns ``(status, goal code, expansions so far, codes touched)``.
    """
    N = h.shape[0]
    heap = [(h[s], 0, s)]
    best[s] = 0
    par_code[s] = -1
    par_t[s] = 0
    touched[0] = s
    nt = 1
    while len(heap) > 0:
        item = heapq.heappop(heap)
        code = item[2]
        t_u = -item[1]
        if best[code] < t_u:
            continue
        u = code % N
        b_u = iv_hi[u, code // N]
        if u == g and b_u == forever:
            return FOUND, code, count, nt
        count += 1
        expl[u] = 1
        if budget >= 0 and count > budget:
            return OVER_BUDGET, -1, count, nt
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            hv = h[v]
            if hv >= unreachable:
                continue
            d = durs[e]
            t_hi = b_u - d + 1  # leave by then: u stays free while leaving
            if t_hi < t_u:
                continue
            n_int = iv_n[v]
            j = 0
            if n_int > 1:  # the last interval of v that starts at or before t_u (bisect_right - 1)
                lo, hi = 0, n_int
                while lo < hi:
                    mid = (lo + hi) // 2
                    if iv_lo[v, mid] <= t_u:
                        lo = mid + 1
                    else:
                        hi = mid
                j = lo - 1
                if j < 0:
                    j = 0
            for jv in range(j, n_int):
                a_v = iv_lo[v, jv]
                if a_v > t_hi:
                    break
                b_v = iv_hi[v, jv]
                t = t_u if t_u > a_v else a_v
                last = t_hi if t_hi < b_v - d else b_v - d
                if t > last:
                    continue
                arr = t + d
                key = jv * N + v
                if arr < best[key]:
                    if best[key] == forever:
                        touched[nt] = key
                        nt += 1
                    best[key] = arr
                    par_code[key] = code
                    par_t[key] = t
                    heapq.heappush(heap, (arr + hv, -arr, key))
    return NO_PATH, -1, count, nt


def _reaches_py(indptr: np.ndarray, targets: np.ndarray, open_: np.ndarray, s: int, g: int) -> bool:
    """Whether ``g`` can be reached from ``s`` along the edges (CSR ``indptr``, ``targets``)
    through nodes where ``open_`` is set (``s`` and ``g`` included)."""
    if not (open_[s] and open_[g]):
        return False
    seen = np.zeros(open_.shape[0], dtype=np.uint8)
    stack = np.empty(open_.shape[0], dtype=np.int64)
    seen[s] = 1
    stack[0] = s
    top = 1
    while top > 0:
        top -= 1
        u = stack[top]
        if u == g:
            return True
        for e in range(indptr[u], indptr[u + 1]):
            v = targets[e]
            if open_[v] and not seen[v]:
                seen[v] = 1
                stack[top] = v
                top += 1
    return False


def _block_ranges_py(events: np.ndarray, forever: int, agent: int, hold: int, reach_ptr: np.ndarray,
                     reach_idx: np.ndarray, head: np.ndarray, e_first: np.ndarray, e_last: np.ndarray,
                     e_agent: np.ndarray, e_hold: np.ndarray, e_next: np.ndarray, top: int, dirty: np.ndarray,
                     dirty_list: np.ndarray, n_dirty: int) -> Tuple[int, int]:
    """Block what an agent following ``events`` (rows ``(node, time)``, durative time) occupies, then
    parked at its last node from its last time to ``forever``, at every node of each node's reach
    (``reach_idx[reach_ptr[u]:reach_ptr[u + 1]]``: the node and those near it).

    A hold is one row ``(node, last)``: the node is blocked during ``0 .. last``. Each blocked range
    becomes an entry ``(first, last, agent, hold)`` at the head of the node's list (``head``,
    ``e_next``; entries from ``top`` on are free, and the caller makes room). Nodes whose list
    changed are flagged in ``dirty`` and listed in ``dirty_list``. Returns ``(top, n_dirty)``.
    """
    m = events.shape[0]
    for i in range(m):
        u = events[i, 0]
        if hold:
            first, last = 0, events[i, 1]
        elif i + 1 < m:
            first, last = events[i, 1], events[i + 1, 1] - 1
        else:
            first, last = events[i, 1], forever
        for side in range(2):
            x_node = u
            if side == 1:  # a move also occupies the node it goes to, from when it leaves
                if hold or i + 1 >= m or events[i + 1, 0] == u:
                    break
                x_node = events[i + 1, 0]
            for r in range(reach_ptr[x_node], reach_ptr[x_node + 1]):
                x = reach_idx[r]
                e = top
                top += 1
                e_first[e] = first
                e_last[e] = last
                e_agent[e] = agent
                e_hold[e] = hold
                e_next[e] = head[x]
                head[x] = e
                if not dirty[x]:
                    dirty[x] = 1
                    dirty_list[n_dirty] = x
                    n_dirty += 1
    return top, n_dirty


def _drop_holds_py(node: int, agent: int, reach_ptr: np.ndarray, reach_idx: np.ndarray, head: np.ndarray,
                   e_agent: np.ndarray, e_hold: np.ndarray, e_next: np.ndarray, dirty: np.ndarray,
                   dirty_list: np.ndarray, n_dirty: int) -> int:
    """Unlink ``agent``'s hold entries from the lists of the reach of ``node`` (see
    :func:`block_ranges`); returns the new ``n_dirty``."""
    for r in range(reach_ptr[node], reach_ptr[node + 1]):
        x = reach_idx[r]
        prev = -1
        e = head[x]
        while e >= 0:
            nxt = e_next[e]
            if e_agent[e] == agent and e_hold[e]:
                if prev < 0:
                    head[x] = nxt
                else:
                    e_next[prev] = nxt
            else:
                prev = e
            e = nxt
        if not dirty[x]:
            dirty[x] = 1
            dirty_list[n_dirty] = x
            n_dirty += 1
    return n_dirty


def _refresh_intervals_py(dirty_list: np.ndarray, begin: int, n_dirty: int, dirty: np.ndarray, head: np.ndarray,
                          e_first: np.ndarray, e_last: np.ndarray, e_next: np.ndarray, iv_lo: np.ndarray,
                          iv_hi: np.ndarray, iv_n: np.ndarray, forever: int) -> Tuple[int, int]:
    """The safe intervals (the maximal ranges no entry blocks, see :func:`block_ranges`) of the
    nodes ``dirty_list[begin:n_dirty]``, written to ``iv_lo``, ``iv_hi``, ``iv_n`` and unflagged in
    ``dirty``. Returns ``(n_dirty, 0)`` when done, or ``(i, m)`` where node ``dirty_list[i]`` needs
    ``m`` intervals, more than ``iv_lo`` has room for (the caller grows it and goes on from ``i``)."""
    cap = iv_lo.shape[1]
    for i in range(begin, n_dirty):
        x = dirty_list[i]
        count = 0
        e = head[x]
        while e >= 0:
            count += 1
            e = e_next[e]
        firsts = np.empty(count, dtype=np.int64)
        lasts = np.empty(count, dtype=np.int64)
        e = head[x]
        j = 0
        while e >= 0:
            firsts[j] = e_first[e]
            lasts[j] = e_last[e]
            j += 1
            e = e_next[e]
        order = np.argsort(firsts)
        # count the intervals first, so that nothing is written where there is no room
        m = 0
        nxt = 0
        for j in range(count):
            a = firsts[order[j]]
            b = lasts[order[j]]
            if a > nxt:
                m += 1
            if b + 1 > nxt:
                nxt = b + 1
        if nxt <= forever:
            m += 1
        if m > cap:
            return i, m
        m = 0
        nxt = 0
        for j in range(count):
            a = firsts[order[j]]
            b = lasts[order[j]]
            if a > nxt:
                iv_lo[x, m] = nxt
                iv_hi[x, m] = a - 1
                m += 1
            if b + 1 > nxt:
                nxt = b + 1
        if nxt <= forever:
            iv_lo[x, m] = nxt
            iv_hi[x, m] = forever
            m += 1
        iv_n[x] = m
        dirty[x] = 0
    return n_dirty, 0


if _numba is not None:  # pragma: no branch
    sipp_durative = _numba.njit(cache=True, nogil=True)(_sipp_durative_py)
    reaches = _numba.njit(cache=True, nogil=True)(_reaches_py)
    block_ranges = _numba.njit(cache=True, nogil=True)(_block_ranges_py)
    drop_holds = _numba.njit(cache=True, nogil=True)(_drop_holds_py)
    refresh_intervals = _numba.njit(cache=True, nogil=True)(_refresh_intervals_py)
else:  # pragma: no cover - depends on the environment
    sipp_durative = _sipp_durative_py
    reaches = _reaches_py
    block_ranges = _block_ranges_py
    drop_holds = _drop_holds_py
    refresh_intervals = _refresh_intervals_py

__all__ = ["AVAILABLE", "ENABLED", "active", "block_ranges", "drop_holds", "reaches", "refresh_intervals",
           "sipp_durative"]
