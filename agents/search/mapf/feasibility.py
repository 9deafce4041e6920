"""Whether any plan exists at all: an exhaustive search over the agents' joint configurations.

Search-based solvers tell "no plan exists" from "no plan found yet" only by exhausting their
search tree, which on an impossible instance can take as long as their time limit. Where the
instance is small enough to enumerate its joint configurations (every placement of the agents
on distinct nodes, at most ``max_states`` of them), :func:`joint_feasible` decides
feasibility exactly: a search from the starts over joint moves (greedy, towards the goals,
so that a feasible instance ends early; exhaustive when it is not), where in one
step every agent waits or moves along an edge, no two agents end on the same node or on near
nodes, and no two swap along an edge. The goals are reached together iff the search meets the
goal configuration (an agent may pass its goal before its final arrival).

This is the unit-time semantics. Every durative plan can be serialised into a unit-time plan
(each move taken in the step it starts; the durative model's occupancy of both ends during a
move forbids everything the unit model forbids), so "no unit-time plan" also proves that no
durative plan exists. Corridors with a pocket that cannot let all agents pass, rings and trees
filled beyond what rotations and exchanges allow are the typical cases.
"""
from __future__ import annotations

import heapq
import math
from typing import Dict, List, Optional, Tuple

from .instance import MapfInstance

#: default ``max_states``: joint configurations a check may enumerate
DEFAULT_MAX_STATES = 100_000


def configuration_count(n_nodes: int, n_agents: int) -> int:
    """How many placements of ``n_agents`` distinct agents on distinct nodes exist."""
    if n_agents > n_nodes:
        return 0
    return math.perm(n_nodes, n_agents)


def joint_feasible(inst: MapfInstance, max_states: int = DEFAULT_MAX_STATES) -> Optional[bool]:
    """``True`` if all agents can reach their goals together, ``False`` if provably not, ``None``
    when the search met ``max_states`` configurations undecided (the instance is too large).

    Starts and goals must be valid configurations (distinct, not near each other); otherwise the
    answer is ``False``.
    """
    if max_states < 1:
        raise ValueError(f"max_states must be >= 1, got {max_states!r}")
    near = inst.near_mat
    succ = inst.succ
    k = inst.n_agents
    start, goal = tuple(inst.starts), tuple(inst.goals)
    for conf in (start, goal):
        for a in range(k):
            for b in range(a + 1, k):
                if conf[a] == conf[b] or (near is not None and near[conf[a], conf[b]]):
                    return False
    if start == goal:
        return True
    h = inst.h
    seen = {start}
    heap: List[Tuple[int, Tuple[int, ...]]] = [(0, start)]
    while heap:
        _, conf = heapq.heappop(heap)
        for new in _joint_moves(conf, succ, near):
            if new in seen:
                continue
            if new == goal:
                return True
            seen.add(new)
            if len(seen) > max_states:
                return None
            heapq.heappush(heap, (sum(h[i][v] for i, v in enumerate(new)), new))
    return False


def _joint_moves(conf: Tuple[int, ...], succ: List[List[int]], near) -> List[Tuple[int, ...]]:
    """Every configuration one joint step from ``conf`` (vertex, swap and proximity rules)."""
    k = len(conf)
    out: List[Tuple[int, ...]] = []
    chosen: List[int] = []
    where: Dict[int, int] = {v: i for i, v in enumerate(conf)}

    def place(i: int) -> None:
        if i == k:
            out.append(tuple(chosen))
            return
        u = conf[i]
        for v in succ[u]:
            ok = True
            for j in range(i):
                w = chosen[j]
                if w == v or (near is not None and near[w, v]):
                    ok = False
                    break
            if not ok:
                continue
            if v != u:
                other = where.get(v)
                if other is not None and other < i and chosen[other] == u:
                    continue  # agents i and j would swap along the edge u - v
            chosen.append(v)
            place(i + 1)
            chosen.pop()

    place(0)
    return out
