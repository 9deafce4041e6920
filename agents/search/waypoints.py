"""Waypoints for the controller without a planner's graph: the waypoints of solver paths, and
plans that head straight for the goal."""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .execution.controller import AgentPlan


def direct_plans(goals: np.ndarray, names: Optional[Sequence[str]] = None) -> Dict[str, AgentPlan]:
    """Plans without search: every agent heads straight for its goal."""
    goals = np.asarray(goals)
    names = list(names) if names is not None else [f"agent_{i}" for i in range(len(goals))]
    return {n: AgentPlan(waypoints=goals[:0], goal=goals[i]) for i, n in enumerate(names)}


def waypoints_from_paths(paths: Sequence[Sequence[Tuple[int, int]]]):
    """Split CBS timed paths into per-agent waypoints.

    A path is ``[(node, time), ...]``; repeated nodes are waits. Returns ``(nodes,
    depart_times, node_arrivals, arrivals)``: per agent the nodes before the goal, the time it
    leaves each (its last entry there), the time it gets to each (its first entry) and the time
    of its final arrival at the goal.
    """
    all_nodes, all_depart, all_arrive, arrivals = [], [], [], []
    for path in paths:
        if not path:
            raise ValueError("empty path")
        nodes: List[int] = []
        depart: List[int] = []
        arrive: List[int] = []
        for node, t in path[:-1]:
            if nodes and nodes[-1] == node:
                depart[-1] = int(t)
            else:
                nodes.append(int(node))
                depart.append(int(t))
                arrive.append(int(t))
        goal, t_end = path[-1]
        if nodes and nodes[-1] == goal:
            # the agent reached its goal earlier and waited there: it arrives at that first visit
            nodes.pop()
            depart.pop()
            arrive.pop()
        all_nodes.append(nodes)
        all_depart.append(depart)
        all_arrive.append(arrive)
        arrivals.append(int(t_end))
    return all_nodes, all_depart, all_arrive, arrivals


__all__ = ["direct_plans", "waypoints_from_paths"]
