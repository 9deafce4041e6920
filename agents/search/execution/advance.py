"""When an agent of :class:`~agents.search.execution.controller.WaypointController` counts its waypoint
as reached (the controller's *advance* rule). A mixin: the controller keeps the state these
methods read and write.

- Below the waypoint's reach threshold: ``reach_threshold``, raised with ``self_margin`` to the
  waypoint's predicted distance to itself plus the margin (a learned distance is not zero there).
- (``settle_patience``) Or once the agent has hovered within ``settle_slack`` of the threshold
  without coming closer for that many steps.
- (``advance_slack``, *on course*) By the threshold, only where the agent is also about as near
  its next target as the waypoint is (below).

*On course*: the agent's predicted distance to the next target (the next waypoint, or the goal
after the last) is at most the waypoint's own predicted distance to it plus ``advance_slack``.
The reach threshold of a panorama waypoint is wide (3 steps, more where the critic puts the
waypoint far from itself), so without this test an agent can count a waypoint reached from a
place from which its policy does not reach the next target, the very place the plan's waypoint
was there to lead it away from (Apartment1: an approach waypoint 0.8 m from an agent's start counted as
reached at once; heading for the goal from the start, the policy left the room through the door
beside it, although from the waypoint it arrives). An agent that settles beside a waypoint
(``settle_patience``) still advances, and so does one that has come no closer to the waypoint (by a
quarter step) for two steps: the test holds an agent only while it closes in on its waypoint (an
agent held where it cannot come closer would soon count as stuck, escape and replan).

*Back first* (``retreat``): an agent whose leg is handed to the fallback policy (it was found stuck
on it) goes back to the waypoint it set off from before the fallback policy drives the leg, to where
it comes no closer to that waypoint within its reach threshold; ``"goal"``: only on the leg to the
goal, ``"any"``: on every leg but the first. Counted reached from up to a metre away, a waypoint at a
corner can be left on the wrong side of the corner, and an agent found stuck on the next leg has
mostly slid further along the wall the wrong way; from there neither policy may reach its target
(Apartment3: a wall end at (10, 2.2) m with a goal behind it, where an agent of a traced run tried
three approaches and arrived at step 73; going back, it arrives at step 31).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, Tuple

import numpy as np

from ..config import ControllerConfig


class AdvanceRules:
    """The controller's rules for a reached waypoint (see the module's docstring)."""

    config: ControllerConfig
    t: int
    index: Dict[str, int]
    _thresholds: Dict[str, np.ndarray]
    #: per agent: (target index, closest predicted distance, step it came that close)
    _progress: Dict[str, Tuple[int, float, int]]
    plans: Dict[str, Any]
    distance: Callable[[np.ndarray, np.ndarray], np.ndarray]
    stats: Any
    #: per agent, within the reach threshold: (waypoint index, closest predicted distance, step it came that close)
    _approach: Dict[str, Tuple[int, float, int]]
    #: per agent: the plan the onward distances are of, and per waypoint its predicted distance to the next target
    _onward: Dict[str, Tuple[Any, np.ndarray]]
    #: per agent going back first: the index of the target whose leg it went back from
    _back: Dict[str, int]
    #: per agent going back: (waypoint index, closest predicted distance, step it came that close)
    _back_best: Dict[str, Tuple[int, float, int]]
    #: the controller's no-progress record (reset where the target changes)
    _best: Dict[str, Tuple[int, float, int]]

    def _reach_thresholds(self, plan: Any) -> np.ndarray:
        """Per waypoint of ``plan``: the predicted distance below which it counts as reached."""
        k = len(plan.waypoints)
        thr = np.full(k, self.config.reach_threshold)
        if self.config.self_margin is not None and k:
            wps = np.asarray(plan.waypoints)
            own = np.asarray(self.distance(wps, wps), dtype=np.float64).reshape(k)
            thr = np.maximum(thr, own + self.config.self_margin)
        return thr

    def reach_threshold_of(self, agent: str) -> float:
        """The threshold below which ``agent``'s current waypoint counts as reached (``inf`` past the last)."""
        k = self.index[agent]
        thr = self._thresholds[agent]
        return float(thr[k]) if k < len(thr) else math.inf

    def _closest(self, store: Dict[str, Tuple[int, float, int]], agent: str, k: int,
                 d: float) -> Tuple[int, float, int]:
        """``agent``'s closest predicted approach to waypoint ``k`` as kept in ``store``: (``k``, that
        distance, the step it came that close), begun anew for a new waypoint or one closer by a quarter step."""
        best = store.get(agent)
        if best is None or best[0] != k or d < best[1] - 0.25:
            store[agent] = best = (k, d, self.t)
        return best

    def _settled(self, agent: str, k: int, d: float) -> bool:
        """Track ``agent``'s closest predicted approach to waypoint ``k``; ``True`` once it is within
        ``settle_slack`` of the threshold and has not come closer for ``settle_patience`` steps (an
        agent pressed against a wall with the waypoint behind it reads far, and is not settled)."""
        if self.config.settle_patience is None or not math.isfinite(d):
            return False
        best = self._closest(self._progress, agent, k, d)
        near = self._thresholds[agent][k] + self.config.settle_slack
        if d < near and best[1] < near and self.t - best[2] >= self.config.settle_patience:
            self.stats.settled += 1
            return True
        return False

    def _onward_distances(self, agent: str) -> np.ndarray:
        """Per waypoint of ``agent``'s plan: its predicted distance to the next target."""
        plan = self.plans[agent]
        cached = self._onward.get(agent)
        if cached is None or cached[0] is not plan:
            wps = np.asarray(plan.waypoints)
            nxt = np.concatenate([wps[1:], np.asarray(plan.goal)[None]])
            cached = self._onward[agent] = (plan, np.asarray(self.distance(wps, nxt), dtype=np.float64).reshape(-1))
        return cached[1]

    def _on_course(self, agent: str, k: int, observation: np.ndarray, d: float) -> bool:
        """Whether ``agent``, at predicted distance ``d`` (within the reach threshold) from waypoint ``k``,
        is about as near the next target as that waypoint, or comes no closer to the waypoint (always,
        without ``advance_slack``)."""
        if self.config.advance_slack is None:
            return True
        if self.t - self._closest(self._approach, agent, k, d)[2] >= 2:  # no closer for two steps: held no longer
            return True
        plan = self.plans[agent]
        nxt = plan.waypoints[k + 1] if k + 1 < len(plan.waypoints) else plan.goal
        to_next = float(np.asarray(self.distance(observation[None], np.asarray(nxt)[None])).reshape(-1)[0])
        if to_next <= self._onward_distances(agent)[k] + self.config.advance_slack:
            return True
        self.stats.off_course += 1
        return False

    def _go_back(self, agent: str) -> None:
        """With ``retreat``: send ``agent`` back to the waypoint it set off from on its current leg (none
        on its first leg, nor while it already goes back; with ``"goal"``, only on its leg to the goal)."""
        k = self.index[agent]
        n = len(self.plans[agent].waypoints)
        retreat = self.config.retreat
        if retreat is None or agent in self._back or not 1 <= k <= n or retreat == "goal" and k < n:
            return
        self._back[agent] = k
        self._back_best.pop(agent, None)
        self._best.pop(agent, None)
        self.stats.retreats += 1

    def _back_done(self, agent: str, d: float) -> bool:
        """Whether ``agent``, going back and at predicted distance ``d`` from the waypoint it went back to,
        is there: within that waypoint's reach threshold and no closer for two steps (then it resumes its leg)."""
        k = self._back[agent] - 1
        best = self._closest(self._back_best, agent, k, d)
        if d < self._thresholds[agent][k] and self.t - best[2] >= 2:
            del self._back[agent]
            self._best.pop(agent, None)
            return True
        return False


__all__ = ["AdvanceRules"]
