"""Independent check of a multi-agent solution (it shares no code with the CBS search).

:func:`validate` replays every agent's timed path on the graph and lists, in words, everything
wrong with it: wrong start or goal, a move along a missing edge or with the wrong duration,
and every vertex, swap, target and proximity conflict between two agents (agents stay parked
at their goal after their final arrival). An empty list means the solution is valid. It never
raises on a bad solution; it raises ``ValueError`` only on a malformed problem (graph, starts,
goals), like the solver.
"""
from __future__ import annotations

from bisect import bisect_right
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .instance import TIME_MODELS, GraphLike, MapfInstance, ProximityLike, as_proximity, edges_from_graph

_MAX_MESSAGES = 200


def _as_events(path: Any, k: int, problems: List[str]) -> Optional[List[Tuple[int, int]]]:
    """Normalise one agent's path to ``[(node, time), ...]``; record a problem and return None if malformed."""
    try:
        items = list(path)
    except TypeError:
        problems.append(f"agent {k}: path is not a sequence ({type(path).__name__})")
        return None
    if not items:
        problems.append(f"agent {k}: empty path")
        return None
    events: List[Tuple[int, int]] = []
    for idx, item in enumerate(items):
        if isinstance(item, (tuple, list, np.ndarray)):
            if len(item) != 2:
                problems.append(f"agent {k}: entry {idx} {item!r} is not (node, time)")
                return None
            node, t = item
        else:
            node, t = item, idx
        if not isinstance(node, (int, np.integer)) or not isinstance(t, (int, np.integer)) \
                or isinstance(node, bool) or isinstance(t, bool):
            problems.append(f"agent {k}: entry {idx} {item!r} must hold integers")
            return None
        events.append((int(node), int(t)))
    return events


def validate(
    graph: Union[GraphLike, MapfInstance],
    starts: Optional[Sequence[int]],
    goals: Optional[Sequence[int]],
    paths: Sequence[Any],
    *,
    time_model: str = "unit",
    proximity: ProximityLike = None,
) -> List[str]:
    """List every violation of a multi-agent solution (empty list: valid).

    Args:
        graph: the problem's graph (as for :class:`~agents.search.mapf.instance.MapfInstance`),
            or a ``MapfInstance`` (then ``starts``, ``goals``, ``time_model`` and ``proximity``
            are taken from it when passed as ``None``).
        starts, goals: one node per agent.
        paths: per agent, either a sequence of nodes (one per time step) or of ``(node, time)``
            pairs with increasing times (a repeated node means waiting; under the durative model
            consecutive different nodes must be exactly the edge's duration apart).
        time_model: ``"unit"`` or ``"durative"`` (see :mod:`agents.search.mapf`).
        proximity: optional :class:`~agents.search.mapf.instance.Proximity` or ``(node_dist, radius)``.

    Returns:
        Human-readable violations, e.g. ``"vertex conflict: agents 0 and 2 at node 5 at t=3"``.
    """
    if isinstance(graph, MapfInstance):
        inst = graph
        starts = inst.starts if starts is None else starts
        goals = inst.goals if goals is None else goals
        time_model = inst.time_model
        proximity = inst.proximity if proximity is None else proximity
        n = inst.n_nodes
        edges: Dict[Tuple[int, int], float] = {}
        for u in range(n):
            for v, d in inst.succ_d[u][1:]:
                edges[(u, v)] = d
    else:
        n, edges = edges_from_graph(graph)
    if time_model not in TIME_MODELS:
        raise ValueError(f"time_model must be one of {TIME_MODELS}, got {time_model!r}")
    unit = time_model == "unit"
    prox = as_proximity(proximity)
    near = prox.near_matrix(n) if prox is not None else None
    if starts is None or goals is None:
        raise TypeError("starts and goals are required unless graph is a MapfInstance")
    starts = [int(s) for s in starts]
    goals = [int(g) for g in goals]
    if len(starts) != len(goals):
        raise ValueError(f"{len(starts)} starts but {len(goals)} goals")

    problems: List[str] = []
    k_agents = len(starts)
    try:
        n_paths = len(paths)
    except TypeError:
        return [f"paths must be a sequence with one path per agent, got {type(paths).__name__}"]
    if n_paths != k_agents:
        problems.append(f"{n_paths} paths for {k_agents} agents")

    ok: Dict[int, List[Tuple[int, int]]] = {}
    for k in range(min(n_paths, k_agents)):
        events = _as_events(paths[k], k, problems)
        if events is None:
            continue
        good = True
        for node, _ in events:
            if not 0 <= node < n:
                problems.append(f"agent {k}: node {node} is not in the graph")
                good = False
                break
        if not good:
            continue
        if events[0] != (starts[k], 0):
            problems.append(f"agent {k}: starts at {events[0]} instead of ({starts[k]}, 0)")
            good = False
        if events[-1][0] != goals[k]:
            problems.append(f"agent {k}: ends at node {events[-1][0]} instead of its goal {goals[k]}")
            good = False
        for (u, t0), (v, t1) in zip(events, events[1:]):
            dt = t1 - t0
            if dt <= 0:
                problems.append(f"agent {k}: time goes from {t0} to {t1} (must increase)")
                good = False
                break
            if u == v:
                continue
            dur = edges.get((u, v))
            if dur is None:
                problems.append(f"agent {k}: moves {u}->{v} at t={t0} but there is no such edge")
                good = False
                continue
            need = 1 if unit else int(round(dur))
            if dt != need:
                problems.append(f"agent {k}: move {u}->{v} at t={t0} takes {dt} steps, the edge takes {need}")
                good = False
        if good:
            ok[k] = events

    if len(ok) >= 2:
        problems.extend(_conflicts(ok, unit, near))
    if len(problems) > _MAX_MESSAGES:
        extra = len(problems) - _MAX_MESSAGES
        problems = problems[:_MAX_MESSAGES] + [f"... and {extra} more"]
    return problems


def _occupied_at(events: List[Tuple[int, int]], times: List[int], t: int, unit: bool) -> Tuple[int, ...]:
    """The nodes an agent following ``events`` occupies at time ``t`` (unit) / during step
    ``[t, t + 1)`` (durative): the node it is at or waits at, or both ends of the edge it is
    traversing; from its final arrival on, its goal."""
    i = bisect_right(times, t) - 1
    if i >= len(events) - 1:
        return (events[-1][0],)
    u, v = events[i][0], events[i + 1][0]
    return (u,) if (unit or u == v) else (u, v)


def _spans(events: List[Tuple[int, int]], horizon: int, unit: bool) -> List[Tuple[int, int, int]]:
    """``(node, first, last)``: the inclusive ranges of times (unit) / steps (durative) in which
    an agent following ``events`` occupies each node, up to ``horizon`` (then parked at its goal)."""
    out: List[Tuple[int, int, int]] = []
    for (u, t0), (v, t1) in zip(events, events[1:]):
        out.append((u, t0, t1 - 1))
        if not unit and u != v:
            out.append((v, t0, t1 - 1))
    out.append((events[-1][0], events[-1][1], horizon))
    return out


def _conflicts(ok: Dict[int, List[Tuple[int, int]]], unit: bool, near: Optional[np.ndarray]) -> List[str]:
    """Every conflict between two agents, ordered by the pair, then by time.

    The times at which two agents may conflict are found from the ranges in which they occupy
    each node (the same node, or two near nodes, in overlapping ranges; unit time: opposite moves
    at the same time); each is then checked from both agents' occupation at that time."""
    agents = sorted(ok)
    arrive = {k: ok[k][-1][1] for k in agents}
    horizon = max(arrive.values()) + 1
    at_node: Dict[int, List[Tuple[int, int, int]]] = {}
    for k in agents:
        for node, first, last in _spans(ok[k], horizon, unit):
            at_node.setdefault(node, []).append((first, last, k))
    candidates = set()

    def overlaps(xs: List[Tuple[int, int, int]], ys: List[Tuple[int, int, int]], same: bool) -> None:
        for i, (f1, l1, a) in enumerate(xs):
            for f2, l2, b in (xs[i + 1:] if same else ys):
                if a == b:
                    continue
                lo, hi = max(f1, f2), min(l1, l2)
                if lo <= hi:
                    pair = (a, b) if a < b else (b, a)
                    for t in range(lo, hi + 1):
                        candidates.add((pair[0], pair[1], t))

    for node, xs in at_node.items():
        overlaps(xs, xs, True)
        if near is not None:
            for other in np.flatnonzero(near[node]).tolist():
                if other > node and other in at_node:
                    overlaps(xs, at_node[other], False)
    if unit:
        moves: Dict[Tuple[int, int, int], List[int]] = {}
        for k in agents:
            for (u, t0), (v, _) in zip(ok[k], ok[k][1:]):
                if u != v:
                    moves.setdefault((u, v, t0), []).append(k)
        for (u, v, t), movers in moves.items():
            for b in moves.get((v, u, t), ()):
                for a in movers:
                    if a < b:
                        candidates.add((a, b, t))
    times = {k: [t for _, t in ok[k]] for k in agents}
    problems: List[str] = []
    where = "at" if unit else "during step"
    for a, b, t in sorted(candidates):
        if t > horizon:
            continue
        ea, eb = ok[a], ok[b]
        sa, sb = _occupied_at(ea, times[a], t, unit), _occupied_at(eb, times[b], t, unit)
        parked = [x for x in (a, b) if t >= arrive[x]]
        tag = f"t={t}" if unit else f"[{t}, {t + 1})"
        hit = None
        for x in sa:
            if x in sb:
                hit = ("vertex", x, x)
                break
        if hit is None and near is not None:
            for x in sa:
                for y in sb:
                    if x != y and near[x, y]:
                        hit = ("proximity", x, y)
                        break
                if hit:
                    break
        if hit is not None:
            kind, x, y = hit
            if len(parked) == 1:
                p = parked[0]
                q, goal_p, node_q = (b, x, y) if p == a else (a, y, x)
                extra = "" if kind == "vertex" else " (within the proximity radius)"
                problems.append(
                    f"target conflict: agent {q} {where} node {node_q} {tag} while agent {p} is parked "
                    f"at its goal {goal_p} since t={arrive[p]}{extra}")
            elif kind == "vertex":
                problems.append(f"vertex conflict: agents {a} and {b} {where} node {x} {tag}")
            else:
                problems.append(f"proximity conflict: agent {a} {where} node {x} and agent {b} "
                                f"{where} node {y} {tag} are closer than the radius")
        if unit and t < horizon:
            na = _occupied_at(ea, times[a], t + 1, unit)[0]
            nb = _occupied_at(eb, times[b], t + 1, unit)[0]
            if sa[0] != na and sa[0] == nb and na == sb[0]:
                problems.append(f"swap conflict: agents {a} ({sa[0]}->{na}) and {b} ({sb[0]}->{nb}) "
                                f"traverse the same edge in opposite directions at t={t}")
    return problems
