"""The order in which a multi-agent plan passes shared places: a temporal plan graph.

A plan made on predicted durations is not kept on the clock: a learned policy is slower or
faster than its critic predicts, gets stuck and escapes. Executing by the clock then lets an
agent that is late meet another one where the plan had them pass one after the other. Action
dependency graphs / temporal plan graphs (Hönig et al. 2019) keep the plan's *order* instead:
whenever two agents visit nearby nodes, the one the plan sends there second may not set off for
its node before the first has got far enough along its own route.

:func:`plan_dependencies` reads these orderings off a plan: for agent ``j`` and each target index
``q`` of its route (a waypoint, or its goal at ``q = len(route)``), the pairs ``(i, r)`` such that
``j`` may head for target ``q`` only once agent ``i`` has reached its target ``r`` and set off from
it (or has arrived). The plan orders *arrivals* (``i`` reaches ``r`` before ``j`` reaches ``q``),
the controller gates *departures* (``j`` sets off for ``q`` only after ``i`` left ``r``), which is
stricter: two agents that swap places in a corridor can each wait for the other to leave first.
Where such waits close a cycle, the dependency in it that is furthest behind in plan time is
weakened to the latest target of ``i`` that the plan has it leave before ``j`` sets off (dropped
when there is none), until no cycle is left: an execution that respects the result cannot
deadlock on it.
"""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import breadth_first_order

from .repair import near_either_way

#: per agent: target index -> the (agent, target index) pairs that must be reached first
Dependencies = List[Dict[int, List[Tuple[int, int]]]]


def plan_dependencies(
    routes: Sequence[Sequence[int]],
    arrivals: Sequence[Sequence[int]],
    departures: Sequence[Sequence[int]],
    goals: Sequence[int],
    goal_arrivals: Sequence[int],
    close: np.ndarray,
) -> Dependencies:
    """The plan-order dependencies between agents (see the module docstring).

    Args:
        routes: per agent, the node ids of its route (its start first, its goal excluded).
        arrivals: per agent, the plan time at which it reaches each node of its route.
        departures: per agent, the plan time at which it leaves each node of its route.
        goals: per agent, its goal's node id.
        goal_arrivals: per agent, the plan time at which it reaches its goal.
        close: ``close[u, v]``: nodes ``u`` and ``v`` are near enough for two agents there to
            conflict (the planner's proximity relation).

    Returns:
        per agent ``j``: ``{q: [(i, r), ...]}``: ``j`` may set off for its target ``q`` only once
        agent ``i`` has reached its target ``r`` (``r = len(routes[i])``: arrived at its goal).
        Of several visits of ``i`` near one target of ``j``, only the latest that the plan puts
        before ``j``'s arrival counts; when ``i`` also reaches its next target before that
        arrival, ``j`` waits for that one (``i`` has left the place, not just got there). The
        dependencies have no cycle (see the module docstring).
    """
    k = len(routes)
    if not (len(arrivals) == len(departures) == len(goals) == len(goal_arrivals) == k):
        raise ValueError(f"routes, arrivals, departures, goals and goal_arrivals must have one entry per agent ({k})")
    nodes = []
    times = []
    for a in range(k):
        if len(arrivals[a]) != len(routes[a]):
            raise ValueError(f"agent {a}: {len(routes[a])} route nodes but {len(arrivals[a])} arrival times")
        if len(departures[a]) != len(routes[a]):
            raise ValueError(f"agent {a}: {len(routes[a])} route nodes but {len(departures[a])} departure times")
        nodes.append(np.asarray([*routes[a], goals[a]], dtype=np.int64))
        times.append(np.asarray([*arrivals[a], goal_arrivals[a]], dtype=np.float64))
    out: Dependencies = [{} for _ in range(k)]
    for j in range(k):
        for i in range(k):
            if i == j:
                continue
            ti, tj = times[i], times[j]
            mask = close[np.ix_(nodes[i], nodes[j])] & (ti[:, None] < tj[None, :])
            mask[:, 0] = False  # j stands on its start already
            for q in np.flatnonzero(mask.any(axis=0)).tolist():
                m = int(np.flatnonzero(mask[:, q]).max())
                r = m + 1 if m + 1 < len(ti) and ti[m + 1] < tj[q] else m
                out[j].setdefault(q, []).append((i, r))
    # plan time of "a sets off for its target q" (q = len(route) + 1: a has arrived)
    leaves = [np.asarray([*departures[a], goal_arrivals[a]], dtype=np.float64) for a in range(k)]
    while True:
        cycle = _wait_cycle(out, [len(r) for r in routes])
        if cycle is None:
            return out
        j, q, i, r = max(cycle, key=lambda e: leaves[e[2]][e[3]] - leaves[e[0]][e[1] - 1])
        out[j][q].remove((i, r))
        before = np.flatnonzero(leaves[i][:r] < leaves[j][q - 1])
        if len(before):
            out[j][q].append((i, int(before.max())))
        if not out[j][q]:
            del out[j][q]


def _wait_cycle(deps: Dependencies, lengths: Sequence[int]) -> Optional[List[Tuple[int, int, int, int]]]:
    """A cycle of waits in ``deps`` as its dependencies ``(j, q, i, r)``, or ``None``.

    Events are ``(a, q)``: agent ``a`` sets off for its target ``q`` (``q = lengths[a] + 1``: it
    arrives); ``(a, q)`` follows ``(a, q - 1)``, and a dependency ``(i, r)`` of ``j``'s target ``q``
    makes ``(j, q)`` follow ``(i, r + 1)``."""
    into: Dict[Tuple[int, int], List[Tuple[Tuple[int, int], Optional[Tuple[int, int, int, int]]]]] = {}
    for j, d in enumerate(deps):
        for q in range(2, lengths[j] + 2):
            into.setdefault((j, q), []).append(((j, q - 1), None))
        for q, pairs in d.items():
            for i, r in pairs:
                into.setdefault((j, q), []).append(((i, r + 1), (j, q, i, r)))
    # depth-first search backwards along "follows"; a node met again on the stack closes a cycle
    state: Dict[Tuple[int, int], int] = {}
    for root in into:
        if state.get(root):
            continue
        stack = [(root, iter(into.get(root, [])))]
        path: List[Optional[Tuple[int, int, int, int]]] = []
        state[root] = 1
        while stack:
            node, it = stack[-1]
            step = next(it, None)
            if step is None:
                state[node] = 2
                stack.pop()
                if path:
                    path.pop()
                continue
            prev, dep = step
            if state.get(prev) == 1:  # back on the stack: the edges from there to here, and this one
                at = [n for n, _ in stack].index(prev)
                edges = path[at:] + [dep]
                return [e for e in edges if e is not None]
            if not state.get(prev):
                state[prev] = 1
                stack.append((prev, iter(into.get(prev, []))))
                path.append(dep)
    return None


def proximity_relation(D: np.ndarray, radius: float, n_buffer: int, n_agents: int) -> np.ndarray:
    """``close[u, v]`` over a problem graph's nodes (buffer nodes, then starts, then goals): predicted
    distance below ``radius`` in either direction; starts among themselves and goals among themselves
    are not close (the planner exempts them: agents placed or parked side by side)."""
    close = np.minimum(D, D.T) < radius
    np.fill_diagonal(close, True)  # a learned distance from a node to itself is not zero
    for lo in (n_buffer, n_buffer + n_agents):
        close[lo:lo + n_agents, lo:lo + n_agents] = False
    return close


def goal_passers(problem: Any, goal: int, others: Mapping[str, Tuple[Sequence[int], Any, int, int]],
                 radius: float) -> List[Tuple[str, int]]:
    """The agents whose remaining routes pass the goal node ``goal`` of ``problem``, each with the
    target index it must reach (leave the place) before an agent may park there.

    A leg passes the goal when its end is within ``radius`` predicted steps of it (the
    planner's own conflict, on the routes as they are now: routes made by replans are in no plan
    order), or when the goal lies on the way: going through it is at most ``radius`` longer than
    the leg, which the planner does not see. Two goals side by side do not count (the planner
    lets agents park so).

    Args:
        problem: the problem graph of the parking agent (``D``, ``n_buffer``).
        goal: its goal's node id there.
        others: per other agent, ``(route, its problem graph, its goal's id there, its current
            target index)``; buffer node ids are shared between problem graphs, an agent's own
            start and goal only when it was planned on ``problem`` too.
        radius: the proximity radius (predicted steps).
    """
    D = problem.D
    out: List[Tuple[str, int]] = []
    for b, (route, pb, gb, k) in others.items():
        nodes = [*route, gb]
        ids = [u if (u < problem.n_buffer or pb is problem) else -1 for u in nodes]
        last = -1
        for q in range(max(k, 1), len(nodes)):
            u, v = ids[q - 1], ids[q]
            near = v >= 0 and min(D[v, goal], D[goal, v]) < radius
            if near and q == len(route):
                continue  # goals side by side
            if near:
                last = q + 1 if q + 1 < len(nodes) else q
            elif u >= 0 and v >= 0 and D[u, goal] + D[goal, v] <= D[u, v] + radius:
                last = q
        if last >= 0:
            out.append((b, last))
    return out


def shut_out(problem: Any, goal: int, others: Mapping[str, Tuple[Sequence[int], Any, int, int]], clearance: float,
             cache: Optional[Dict[Tuple[int, ...], bool]] = None) -> List[Tuple[str, int]]:
    """The agents that an agent parked at ``goal`` would shut out, each with its goal's target index.

    An agent is shut out when its goal is reachable on its own problem graph from the node it left
    last, but not without the buffer nodes within ``clearance`` predicted steps of ``goal`` (a
    goal beside a door or at the end of a corridor: agents park where they first come within the
    goal radius, so the parked agent can stand in the passage).

    Args:
        problem: the problem graph of the parking agent; goal: its goal's id there.
        others: per agent still under way, as for :func:`goal_passers`.
        clearance: predicted steps around ``goal``.
        cache: optional dict that keeps the answers (keyed by the graphs' ids and the nodes).
    """
    near = nodes_near(problem, goal, clearance)
    cache = {} if cache is None else cache
    out: List[Tuple[str, int]] = []
    for b, (route, pb, gb, k) in others.items():
        source = route[k - 1] if 1 <= k <= len(route) else (route[0] if len(route) else None)
        if source is None:
            continue
        key = (id(problem), goal, id(pb), int(source), gb, int(clearance * 1000))
        if key not in cache:
            cache[key] = cut_off(pb.graph.distance, int(source), gb, near)
        if cache[key]:
            out.append((b, len(route)))
    return out


def nodes_near(problem: Any, node: int, radius: float) -> np.ndarray:
    """Mask of the buffer nodes of ``problem`` within ``radius`` predicted steps of ``node``, either way."""
    return near_either_way(problem.D, node, radius, problem.n_buffer)


def cut_off(adjacency: Any, source: int, target: int, banned: np.ndarray) -> bool:
    """Whether ``target`` is reachable from ``source`` in the CSR ``adjacency`` but not without the
    nodes where ``banned`` (a mask over its first nodes) is true (``source`` and ``target`` stay in)."""
    if target not in breadth_first_order(adjacency, source, directed=True, return_predecessors=False):
        return False
    keep = np.ones(adjacency.shape[0])
    keep[:len(banned)] = ~banned
    keep[[source, target]] = 1.0
    without = sparse.diags(keep) @ adjacency @ sparse.diags(keep)  # no edge into or out of a banned node
    return target not in breadth_first_order(without.tocsr(), source, directed=True, return_predecessors=False)


__all__ = ["Dependencies", "cut_off", "goal_passers", "nodes_near", "plan_dependencies", "proximity_relation",
           "shut_out"]
