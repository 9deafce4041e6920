"""The state of one episode of a :class:`~agents.search.policy.SearchPolicy`: one record per agent.

:class:`Episode` holds what the policy knows of the current episode: the agents in planning
order, an :class:`AgentState` per agent (its goal, its last observation, its route and the
problem graph the route lives on, and what its replans keep clear of), the agents seen on the
last call, and the episode's counters. The policy, its replanning
(:class:`~agents.search.execution.replanning.Replanner`) and its goal order read and write it; nothing of it
outlives the episode.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Set, Tuple

import numpy as np

from ..graph.build import ProblemGraph
from .controller import AgentPlan
from .safety import SafetyState


@dataclass(frozen=True)
class Leg:
    """The stretch of its route an agent is on: from the node it left last to its current target.

    Attributes:
        source: buffer node id it left, or ``None`` for its own start (or the place it replanned from).
        target: buffer node id it heads for, or ``None`` for its goal.
        predicted: the critic's predicted steps from ``source`` to ``target``.
        started: controller step at which the route holding this leg was planned.
    """

    source: Optional[int]
    target: Optional[int]
    predicted: float
    started: int


@dataclass
class AgentState:
    """What the policy knows of one agent in the current episode.

    Attributes:
        goal: its goal observation.
        last_obs: its observation on the last call it was given (an agent that has arrived keeps
            its last one: where it is parked).
        route: the node ids of its current route on ``problem`` (its start first, its goal left out).
        problem: the problem graph its route lives on (``None``: no planned route).
        goal_id: its goal's node id on ``problem``.
        planned_at: the controller step at which its route was planned.
        banned: buffer nodes its replans keep clear of from now on.
        failed: the waypoint nodes it failed to reach since its last full plan.
        failed_edges: the buffer edges it failed on this episode (left out of its replans).
        detached: buffer nodes its replans may not link its start to (it failed to reach them).
        goal_detached: buffer nodes its replans may not link to its goal (it failed to reach its goal
            from them).
        seen_index: the waypoint index last seen (the edges it got through since go to the edge memory).
        leg_checked: the leg (controller plan, target index) ``repair_routes`` checked last.
    """

    goal: np.ndarray
    last_obs: Optional[np.ndarray] = None
    route: List[int] = field(default_factory=list)
    problem: Optional[ProblemGraph] = None
    goal_id: int = -1
    planned_at: int = 0
    banned: List[int] = field(default_factory=list)
    failed: List[int] = field(default_factory=list)
    failed_edges: List[Tuple[int, int]] = field(default_factory=list)
    detached: List[int] = field(default_factory=list)
    goal_detached: List[int] = field(default_factory=list)
    seen_index: int = 0
    leg_checked: Optional[Tuple[AgentPlan, int]] = None

    def set_route(self, route: List[int], problem: ProblemGraph, goal_id: int, planned_at: int) -> None:
        """A new route on ``problem``, planned at controller step ``planned_at``."""
        self.route, self.problem, self.goal_id, self.planned_at = list(route), problem, int(goal_id), planned_at
        self.seen_index = 0

    def leg(self, index: int) -> Optional[Leg]:
        """The edge of its route it is on with ``index`` waypoints reached (``None`` without a route)."""
        if self.problem is None:
            return None
        route, problem = self.route, self.problem
        target = route[index] if index < len(route) else self.goal_id
        source = route[index - 1] if index > 0 else None
        n = problem.n_buffer
        predicted = math.nan if source is None else float(problem.D[source, target])

        def buffer_id(i: Optional[int]) -> Optional[int]:
            return None if i is None or i >= n else int(i)

        return Leg(buffer_id(source), buffer_id(target), predicted, self.planned_at)

    def rest_of_route(self, index: int) -> float:
        """The predicted length of its route from the start of its leg ``index`` to its goal."""
        assert self.problem is not None
        nodes = [*self.route[max(index - 1, 0):], self.goal_id]
        return float(sum(self.problem.D[u, v] for u, v in zip(nodes[:-1], nodes[1:])))


@dataclass
class Episode:
    """The current episode of a :class:`~agents.search.policy.SearchPolicy`.

    Attributes:
        agents: agent names in planning order.
        states: per agent, its :class:`AgentState`.
        live: the agents given on the last call (the others have arrived, or left).
        planning_time: seconds spent on the episode's first plan; ``replan_time``: on the replans since.
        narrow_replans: replans that kept clear of the failed waypoints alone (``ban_detour``).
        route_repairs: replans before a leg along an edge another agent failed on (``repair_routes``).
        safety: what the safety layer did.
    """

    agents: List[str] = field(default_factory=list)
    states: Dict[str, AgentState] = field(default_factory=dict)
    live: Set[str] = field(default_factory=set)
    planning_time: float = 0.0
    replan_time: float = 0.0
    narrow_replans: int = 0
    route_repairs: int = 0
    safety: SafetyState = field(default_factory=SafetyState)
    #: :func:`~agents.search.execution.dependencies.shut_out`'s cache of cuts found
    cut_cache: Dict[Tuple[int, ...], bool] = field(default_factory=dict)

    def parked(self, agent: str) -> List[str]:
        """The agents other than ``agent`` not given on the last call: arrived, parked where last seen."""
        return [b for b in self.agents if b != agent and b not in self.live]

    def routed(self) -> List[str]:
        """The agents with a planned route, in planning order."""
        return [a for a in self.agents if self.states[a].problem is not None]


__all__ = ["AgentState", "Episode", "Leg"]
