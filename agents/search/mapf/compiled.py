"""Compiled inner loops of the solvers, where numba is installed (optional).

numba is not a dependency: without it, or with ``ENABLED`` set to ``False``, every solver runs
its pure-Python loop. The compiled loops give the same results as the Python ones (the same
states, in the same order, with the same tie-breaks) and count the same work against the same
budgets; only the time differs.

- :func:`sipp_durative`: the safe-interval search of :func:`~agents.search.mapf.sipp.sipp`
  under the durative time model (about 20 times faster on a 6000-node buffer graph);
- :func:`reaches`: whether a node reaches another through open nodes, the test of
  :func:`~agents.search.mapf.prioritized.release_order`.
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


if _numba is not None:  # pragma: no branch
    sipp_durative = _numba.njit(cache=True, nogil=True)(_sipp_durative_py)
    reaches = _numba.njit(cache=True, nogil=True)(_reaches_py)
else:  # pragma: no cover - depends on the environment
    sipp_durative = _sipp_durative_py
    reaches = _reaches_py

__all__ = ["AVAILABLE", "ENABLED", "active", "reaches", "sipp_durative"]
