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

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from .instance import MapfInstance, Proximity

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


def infeasible_component(inst: MapfInstance, max_states: int = DEFAULT_MAX_STATES) -> Optional[str]:
    """Why the instance has no plan, found by :func:`joint_feasible` on each small part, or ``None``.

    The agents are grouped by the weakly connected component of the graph their start lies in
    (components joined where a node of one is near a node of the other, under proximity). An
    agent never leaves its component, so a plan of the whole instance restricted to one group
    is a plan of that group alone on its component: if a group with at most ``max_states``
    joint configurations has none, the instance has none. ``None`` says nothing was proved.
    """
    if inst.n_agents < 2:
        return None
    n_parts, label = connected_components(inst.durations, directed=True, connection="weak")
    if n_parts > 1 and inst.near_mat is not None:
        links = inst.durations + sparse.csr_matrix(inst.near_mat.astype(np.float64))
        _, label = connected_components(links, directed=True, connection="weak")
    groups: Dict[int, List[int]] = {}
    for i, s in enumerate(inst.starts):
        groups.setdefault(int(label[s]), []).append(i)
    for comp, agents in sorted(groups.items(), key=lambda kv: kv[1][0]):
        if len(agents) < 2:
            continue
        nodes = np.flatnonzero(label == comp)
        if configuration_count(len(nodes), len(agents)) > max_states:
            continue
        sub = inst if len(nodes) == inst.n_nodes and len(agents) == inst.n_agents else _restrict(inst, nodes, agents)
        if joint_feasible(sub, max_states) is False:
            n_conf = configuration_count(len(nodes), len(agents))
            who = "the agents'" if sub is inst else f"agents {agents} (on a part of {len(nodes)} nodes):"
            return f"no joint plan exists: an exhaustive search over {who} {n_conf} joint configurations never " \
                   "reaches the goals"
    return None


def _restrict(inst: MapfInstance, nodes: np.ndarray, agents: List[int]) -> MapfInstance:
    """The instance of ``agents`` alone on the graph induced by ``nodes`` (unit time)."""
    index = {int(v): i for i, v in enumerate(nodes)}
    graph = inst.durations[nodes][:, nodes]
    prox = None
    if inst.near_mat is not None:
        prox = Proximity(np.where(inst.near_mat[np.ix_(nodes, nodes)], 0.0, 1.0), 0.5)
    return MapfInstance(graph, [index[inst.starts[i]] for i in agents], [index[inst.goals[i]] for i in agents],
                        time_model="unit", proximity=prox)
