"""Executing waypoint plans in a PettingZoo parallel environment.

Each agent follows its waypoints with a goal-conditioned policy whose goal input is the
current waypoint's observation. Rules, all from observations only:

- **advance**: an agent moves to its next waypoint once the predicted distance to the current
  one falls below ``reach_threshold`` (closed loop), and to its final goal after the last one;
- **plan time**: an agent does not leave waypoint ``k`` before the plan's departure time from
  it (so CBS's waits happen in the environment, too);
- **yield**: when another agent is within ``safety_radius`` (under ``proximity``), the agent
  with the lower priority stands still (priority: the agent further behind its plan goes
  first, ties broken by index); the paper states this rule, we implement it;
- **replan** (optional): a callback asked for a new plan when an agent falls more than
  ``replan_lag`` steps behind its plan.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

PolicyFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
PairFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class AgentPlan:
    """What one agent executes.

    Attributes:
        waypoints: waypoint observations ``(K, ...)`` (K may be 0: go straight to the goal).
        goal: the final goal observation.
        depart_times: for each waypoint, the earliest environment step at which the agent may
            leave it (``None``: leave as soon as it is reached).
    """

    waypoints: np.ndarray
    goal: np.ndarray
    depart_times: Optional[Sequence[int]] = None


@dataclass
class ControllerStats:
    steps: int = 0
    yields: int = 0
    waits: int = 0
    replans: int = 0
    waypoint_index: Dict[str, int] = field(default_factory=dict)


class WaypointController:
    """Turns per-agent plans into actions, one environment step at a time.

    Args:
        policy: ``policy(obs[B, ...], goal[B, ...]) -> actions[B, 2]``, batched over agents.
        distance: ``distance(obs[B, ...], goal[B, ...]) -> [B]`` predicted steps (closed-loop
            advance test).
        plans: agent name -> :class:`AgentPlan`.
        reach_threshold: advance when the predicted distance to the waypoint is below this.
        safety_radius: yield when another agent is closer than this under ``proximity``
            (``None`` disables yielding).
        proximity: ``proximity(obs_a[B, ...], obs_b[B, ...]) -> [B]`` distance between agents'
            observations, in the same units as ``safety_radius`` (default: ``distance``,
            symmetrised by taking the smaller direction).
        replan: optional ``replan(agent, obs, plan) -> AgentPlan`` called when an agent is more
            than ``replan_lag`` steps behind its plan.
    """

    def __init__(
        self,
        policy: PolicyFn,
        distance: PairFn,
        plans: Dict[str, AgentPlan],
        reach_threshold: float = 2.0,
        safety_radius: Optional[float] = 3.0,
        proximity: Optional[PairFn] = None,
        replan: Optional[Callable[[str, np.ndarray, AgentPlan], AgentPlan]] = None,
        replan_lag: int = 20,
    ) -> None:
        self.policy = policy
        self.distance = distance
        self.plans = dict(plans)
        self.reach_threshold = float(reach_threshold)
        self.safety_radius = safety_radius
        self.proximity = proximity
        self.replan = replan
        self.replan_lag = int(replan_lag)
        self.index = {a: 0 for a in self.plans}
        self.t = 0
        self.stats = ControllerStats()

    def current_goal(self, agent: str) -> np.ndarray:
        """The observation agent ``agent`` currently heads for."""
        plan = self.plans[agent]
        k = self.index[agent]
        return plan.waypoints[k] if k < len(plan.waypoints) else plan.goal

    def _lag(self, agent: str) -> int:
        plan = self.plans[agent]
        k = self.index[agent]
        if plan.depart_times is None or k == 0 or k > len(plan.depart_times):
            return 0
        return max(0, self.t - int(plan.depart_times[k - 1]))

    def act(self, observations: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        """Actions for the live agents, given each agent's current observation (the ``observation`` entry)."""
        live = [a for a in observations if a in self.plans]
        if not live:
            return {}
        obs = np.stack([np.asarray(observations[a]) for a in live])
        # advance along waypoints while the current one is reached (several may be close together)
        for _ in range(4):
            goals = np.stack([self.current_goal(a) for a in live])
            d = np.asarray(self.distance(obs, goals), dtype=np.float64)
            moved = False
            for i, a in enumerate(live):
                plan = self.plans[a]
                k = self.index[a]
                if k < len(plan.waypoints) and d[i] < self.reach_threshold:
                    if plan.depart_times is not None and self.t < int(plan.depart_times[k]):
                        continue
                    self.index[a] = k + 1
                    moved = True
            if not moved:
                break
        goals = np.stack([self.current_goal(a) for a in live])
        actions = np.asarray(self.policy(obs, goals), dtype=np.float32).reshape(len(live), -1)
        hold = np.zeros(len(live), dtype=bool)
        # wait at a reached waypoint until the plan's departure time
        for i, a in enumerate(live):
            plan = self.plans[a]
            k = self.index[a]
            if plan.depart_times is not None and k < len(plan.waypoints) and self.t < int(plan.depart_times[k]):
                if self.distance(obs[i:i + 1], goals[i:i + 1])[0] < self.reach_threshold:
                    hold[i] = True
                    self.stats.waits += 1
        if self.safety_radius is not None and len(live) > 1:
            hold |= self._yield_mask(live, obs)
        actions[hold] = 0.0
        if self.replan is not None:
            for i, a in enumerate(live):
                if self._lag(a) > self.replan_lag:
                    self.plans[a] = self.replan(a, obs[i], self.plans[a])
                    self.index[a] = 0
                    self.stats.replans += 1
        self.t += 1
        self.stats.steps = self.t
        self.stats.waypoint_index = dict(self.index)
        return {a: actions[i] for i, a in enumerate(live)}

    def _yield_mask(self, live: List[str], obs: np.ndarray) -> np.ndarray:
        n = len(live)
        ii, jj = np.triu_indices(n, 1)
        if self.proximity is not None:
            prox = np.asarray(self.proximity(obs[ii], obs[jj]), dtype=np.float64)
        else:
            prox = np.minimum(np.asarray(self.distance(obs[ii], obs[jj])), np.asarray(self.distance(obs[jj], obs[ii])))
        close = prox < self.safety_radius
        if not close.any():
            return np.zeros(n, dtype=bool)
        lag = np.array([self._lag(a) for a in live])
        # the agent further behind its plan has priority; ties go to the lower index
        i_first = (lag[ii] > lag[jj]) | ((lag[ii] == lag[jj]) & (ii < jj))
        loser = np.where(i_first, jj, ii)[close]
        winner = np.where(i_first, ii, jj)[close]
        hold = np.zeros(n, dtype=bool)
        # process pairs in priority order so a yielding agent does not also block others
        for w, l in sorted(zip(winner, loser)):
            if not hold[w]:
                hold[l] = True
        self.stats.yields += int(hold.sum())
        return hold


__all__ = ["AgentPlan", "ControllerStats", "WaypointController"]
