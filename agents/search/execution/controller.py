"""Executing waypoint plans in a PettingZoo parallel environment.

Each agent follows its waypoints with a goal-conditioned policy whose goal input is the
current waypoint's observation. Rules, all from observations only:

- **advance**: an agent moves to its next waypoint once the predicted distance to the current
  one falls below its threshold (closed loop), and to its final goal after the last one. The
  threshold is ``reach_threshold``, raised for a waypoint whose own distance to itself (a
  learned distance is not zero there) plus ``self_margin`` is larger: an agent standing on
  such a waypoint would otherwise never see it reached; with ``advance_slack``, only where it is
  about as near its next target as the waypoint is, or no longer closes in on the waypoint
  (:mod:`agents.search.execution.advance`);
- **plan time**: an agent does not leave waypoint ``k`` before the plan's departure time from
  it (so CBS's waits happen in the environment, too);
- **plan order** (optional, instead of plan time): an agent does not set off for a target before
  the agents the plan sends through that place earlier have got far enough along their own
  routes (:mod:`agents.search.execution.dependencies`), however late they are; an agent waits on another
  for at most ``order_patience`` steps in which that one makes no progress, and never on one that
  has replanned;
- **goal order** (optional): an agent does not set off for its goal while ``goal_order`` names
  agents that still have to pass it (an agent parked at its goal is an immovable obstacle, and
  one that parks in a doorway before another has gone through shuts that one out for good);
  same patience as the plan order. Where the two orders meet (the plan sends the parking agent
  first, the goal order holds it for the other), the other agent goes first, and so where the
  holds of several agents close a cycle (:mod:`agents.search.execution.ordering`);
- **clear goal** (optional, ``goal_clearance``; :mod:`agents.search.execution.clearance`): an agent near
  its goal stands still while another agent free to leave stands by that goal (parked, it would
  shut that one in); the one it holds for no longer waits for it by the plan's or goal order;
- **yield**: when another agent is within ``safety_radius`` (under ``proximity``), the agent
  with the lower priority stands still (priority: the agent further behind its plan goes first,
  ties broken by index; with ``goal_clearance``, of two where one stands within it of the goal
  the other is on its way to, the one nearer that goal; with ``push_margin``, one held still
  that the other pushes away from its target); the paper states this rule, we implement it.
  Only two agents that would both move yield to each other: one that already stands still (at
  its waypoint, waiting for its departure time or for an agent the plan sends first) is passed.
  Otherwise an agent waiting for a neighbour to go first can have priority over it, and neither
  moves until ``order_patience`` runs out, again at every waypoint;
- **unstick**: an agent that was free to move but whose observation has hardly changed over
  ``stuck_window`` steps (pressed against furniture, or two agents pushing against each
  other), or (optional) that came no closer to its target for ``progress_patience`` steps (it
  took one place for another and hovers there), takes ``escape_steps`` escape actions (more if
  it gets stuck again): random ones, or (``escape="sidestep"``) a step sideways to the way its
  policy pushes, to one side and at the next escape to the other (an agent that pushes into an
  agent parked on its way slides past it instead of pushing on); stuck ``skip_after`` times on
  the way to the same target, it asks ``replan`` for a new plan from where it stands (without
  one, it gives a waypoint up and heads for the next one). A deterministic policy that pushes
  into a wall would otherwise push there until the episode ends;
- **fallback** (optional): an agent stuck ``skip_after`` times on the way to one target
  hands that leg over to ``fallback_policy`` until it reaches its next waypoint (e.g. a
  constrained policy that will not approach a goal beside furniture hands over to the
  unconstrained one); with ``retreat``, it goes back to the waypoint it set off from first;
- **replan** (optional): a callback asked for a new plan when an agent is stuck (above), or
  when it falls more than ``replan_lag`` steps behind its plan.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..config import ControllerConfig
from .advance import AdvanceRules
from .clearance import GoalClearance, pair_proximity
from .ordering import OrderRules
from .stats import ControllerStats

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
        starts_at_first: the agent stands at ``waypoints[0]`` when the plan begins (the
            planner's start node), so that waypoint counts as reached without asking the
            critic. A learned distance from an observation to itself is not zero (on the
            apartments it is 1.2-3 steps, above a reach threshold of 2), and an agent sent
            towards its own position moves away from it and may never come back.
        after: plan-order dependencies (see :mod:`agents.search.execution.dependencies`).
    """

    waypoints: np.ndarray
    goal: np.ndarray
    depart_times: Optional[Sequence[int]] = None
    starts_at_first: bool = False
    #: target index -> ``(agent, target index)`` pairs that must be reached first (plan order; the
    #: goal is target ``len(waypoints)``, and an agent that has arrived has reached every target)
    after: Optional[Dict[int, List[Tuple[str, int]]]] = None


class WaypointController(GoalClearance, AdvanceRules, OrderRules):
    """Turns per-agent plans into actions, one environment step at a time.

    Args:
        policy: ``policy(obs[B, ...], goal[B, ...]) -> actions[B, 2]``, batched over agents.
        distance: ``distance(obs[B, ...], goal[B, ...]) -> [B]`` predicted steps (closed-loop
            advance test).
        plans: agent name -> :class:`AgentPlan`.
        config: the rules' settings (:class:`~agents.search.config.ControllerConfig`: reach
            threshold, yield radius, unstick, fallback legs, ...); its ``hold`` and
            ``park_clearance`` are read by the policy that makes the plans.
        fallback_policy: optional second ``policy(obs, goal) -> actions`` that drives an agent
            from the moment it is stuck ``skip_after`` times on the way to one target until it
            reaches the next waypoint (or, on its last leg, the goal).
        proximity: ``proximity(obs_a[B, ...], obs_b[B, ...]) -> [B]`` distance between agents'
            observations, in the units of ``safety_radius`` (default: ``distance``, symmetrised
            by taking the smaller direction).
        replan: optional ``replan(agent, obs, plan) -> AgentPlan``, called with the agent's
            current observation when it is stuck (see ``skip_after``) or more than
            ``replan_lag`` steps behind its plan; :attr:`index` still points at the target it
            failed to reach when it is called.
        goal_order: optional ``goal_order(agent) -> [(other, r), ...]``, asked while ``agent``
            stands at its last waypoint: it sets off for its goal only once each ``other`` has
            reached its target ``r`` (or arrived), since ``other``'s route passes ``agent``'s
            goal. Asked afresh at every step (routes change when agents replan); waits as long as
            ``order_patience`` allows. An agent it holds so no longer waits for it by the plan's order.
        bound: optional ``bound(obs_a[N, ...], obs_b[M, ...]) -> (N, M)``, a lower bound of the
            steps between observations that costs no critic call (the env's ``min_steps``, vector
            observations): the yield and clear-goal rules read the critic only on the pairs it puts
            within their radii (``safety_radius``, ``goal_clearance``), so that a step costs about
            as many critic readings as there are agents close to each other, not one per pair.
        seed: seed of the escape actions.
    """

    def __init__(
        self,
        policy: PolicyFn,
        distance: PairFn,
        plans: Dict[str, AgentPlan],
        config: Optional[ControllerConfig] = None,
        *,
        fallback_policy: Optional[PolicyFn] = None,
        proximity: Optional[PairFn] = None,
        replan: Optional[Callable[[str, np.ndarray, AgentPlan], AgentPlan]] = None,
        goal_order: Optional[Callable[[str], List[Tuple[str, int]]]] = None,
        bound: Optional[PairFn] = None,
        seed: Optional[int] = 0,
    ) -> None:
        config = ControllerConfig() if config is None else config
        if not isinstance(config, ControllerConfig):
            raise TypeError(f"config must be a ControllerConfig, got {type(config).__name__}")
        #: the controller's settings
        self.config = config
        self.policy = policy
        self.distance = distance
        self.plans = dict(plans)
        self.fallback_policy = fallback_policy
        self.proximity = proximity
        self.replan = replan
        self.goal_order = goal_order
        self.bound = bound
        self.rng = np.random.default_rng(seed)
        #: per agent: waypoints reached so far, and the count at which its fallback leg began
        self._reached = {a: 0 for a in self.plans}
        self._fallback_at: Dict[str, int] = {}
        #: per agent: times it was found stuck in the episode
        self._stuck_total = {a: 0 for a in self.plans}
        #: per agent: the action of its escape under way (sidestep), and the side of its last one
        self._escape_action: Dict[str, np.ndarray] = {}
        self._side = {a: 1.0 for a in self.plans}
        self._recent: Dict[str, Deque[np.ndarray]] = {a: deque(maxlen=(config.stuck_window or 0) + 1)
                                                      for a in self.plans}
        self._escape = {a: 0 for a in self.plans}
        self._stuck_count = {a: 0 for a in self.plans}
        self.index = {a: 0 for a in self.plans}
        self._at_start = {a: p.starts_at_first and len(p.waypoints) > 0 for a, p in self.plans.items()}
        self._thresholds = {a: self._reach_thresholds(p) for a, p in self.plans.items()}
        self._progress: Dict[str, Tuple[int, float, int]] = {}
        #: per agent: (target index, closest predicted distance, step it was last approached or held)
        self._best: Dict[str, Tuple[int, float, int]] = {}
        #: per agent: target index -> agents (with their target index) to wait for
        self._after = {a: {q: list(v) for q, v in (p.after or {}).items()} for a, p in self.plans.items()}
        #: per agent: (target it may not set off for, agent it waits on, since when, that one's index then)
        self._blocked: Dict[str, Tuple[int, str, int, int]] = {}
        #: per agent: the agents it no longer waits on before parking (its patience ran out)
        self._gave_up: Dict[str, set] = {a: set() for a in self.plans}
        #: agent -> the agent it holds its parking for (goal order), as of its last check
        self._parks_after: Dict[str, str] = {}
        self._waiting: Dict[str, str] = {}
        #: agents reported stuck from outside (a safety layer that kept them from moving), not yet handled
        self._reported: set = set()
        self._onward: Dict[str, Tuple[AgentPlan, np.ndarray]] = {}
        #: per agent: the leg (plan, target index) whose start the ``fallback_beyond`` test has read
        self._leg_read: Dict[str, Tuple[AgentPlan, int]] = {}
        self._back: Dict[str, int] = {}
        self._back_best: Dict[str, Tuple[int, float, int]] = {}
        self._approach: Dict[str, Tuple[int, float, int]] = {}
        self._yielding: Dict[str, Tuple[str, int, float]] = {}
        self._pushed: Dict[Tuple[str, str], str] = {}
        #: agent -> the agent it stands still for to clear its goal (as of the last step); per pair,
        #: the step it began; per agent, those it no longer waits on (its patience ran out)
        self._clearing: Dict[str, str] = {}
        self._clear_since: Dict[Tuple[str, str], int] = {}
        self._clear_gave_up: Dict[str, set] = {a: set() for a in self.plans}
        #: close pairs whose yield priority the goal rule decided, and the agent that goes first
        self._goal_priority: Dict[Tuple[str, str], str] = {}
        self._live: set = set(self.plans)
        self.t = 0
        self.stats = ControllerStats()

    def current_goal(self, agent: str) -> np.ndarray:
        """The observation agent ``agent`` currently heads for."""
        plan = self.plans[agent]
        k = self._back[agent] - 1 if agent in self._back else self.index[agent]
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
        self._live = set(live)
        waiting: Dict[str, str] = {}
        #: predicted distance of each agent to its current target
        to_target: Dict[str, float] = {}
        obs = np.stack([np.asarray(observations[a]) for a in live])
        # advance along waypoints while the current one is reached (several may be close together)
        for _ in range(4):
            goals = np.stack([self.current_goal(a) for a in live])
            d = np.asarray(self.distance(obs, goals), dtype=np.float64)
            d[[self._at_start[a] and self.index[a] == 0 for a in live]] = -np.inf
            moved = False
            for i, a in enumerate(live):
                plan = self.plans[a]
                k = self.index[a]
                to_target[a] = float(d[i])
                if a in self._back:  # going back first: resume the leg once there
                    moved |= self._back_done(a, float(d[i]))
                    continue
                if k >= len(plan.waypoints):
                    continue
                if (d[i] < self._thresholds[a][k] and (d[i] == -np.inf or self._on_course(a, k, obs[i], float(d[i])))
                        or self._settled(a, k, float(d[i]))):
                    if plan.depart_times is not None and self.t < int(plan.depart_times[k]):
                        continue
                    other = self._waits_on(a, k + 1)
                    if other is not None:
                        waiting[a] = other
                        continue
                    waiting.pop(a, None)
                    self._waiting.pop(a, None)
                    self._blocked.pop(a, None)
                    self.index[a] = k + 1
                    self._stuck_count[a] = 0
                    self.stats.leg_escapes[a] = 0
                    to_target.pop(a)
                    if not (k == 0 and self._at_start[a]):
                        self._reached[a] += 1
                    moved = True
            if not moved:
                break
        self._waiting = waiting
        if self.config.fallback_beyond is not None and self.fallback_policy is not None:
            self._hand_over_far_legs(live, to_target)
        goals = np.stack([self.current_goal(a) for a in live])
        actions = np.asarray(self.policy(obs, goals), dtype=np.float32).reshape(len(live), -1)
        if self.fallback_policy is not None:
            fb = [i for i, a in enumerate(live) if self._fallback_at.get(a) == self._reached[a]]
            if fb:
                actions[fb] = np.asarray(self.fallback_policy(obs[fb], goals[fb]),
                                         dtype=np.float32).reshape(len(fb), -1)
                self.stats.fallback_steps += len(fb)
        hold = np.zeros(len(live), dtype=bool)
        reason: List[Optional[str]] = [None] * len(live)
        # wait at a reached waypoint until the plan's departure time
        for i, a in enumerate(live):
            plan = self.plans[a]
            k = self.index[a]
            if plan.depart_times is not None and k < len(plan.waypoints) and self.t < int(plan.depart_times[k]):
                at_start = k == 0 and self._at_start[a]
                if at_start or self.distance(obs[i:i + 1], goals[i:i + 1])[0] < self._thresholds[a][k]:
                    hold[i] = True
                    reason[i] = "wait"
                    self.stats.waits += 1
            elif a in waiting:  # at its waypoint, waiting for an agent the plan sends through first
                hold[i] = True
                reason[i] = f"wait:{waiting[a]}"
                self.stats.waits += 1
        if self.config.goal_clearance is not None and len(live) > 1:
            self._clear_goals(live, obs, hold, reason, to_target)
        if self.config.safety_radius is not None and len(live) > 1:
            yielders = self._yield_mask(live, obs, ~hold, to_target)
            for i, w in yielders.items():
                if not hold[i]:
                    reason[i] = f"yield:{live[w]}"
                hold[i] = True
        self.stats.holding = {a: reason[i] for i, a in enumerate(live)}
        escaping: set = set()
        if self.config.stuck_window is not None:
            escaping = self._unstick(live, obs, hold, actions, to_target)
        actions[hold] = 0.0
        self.stats.activity = {a: self._activity(a, reason[i], a in escaping) for i, a in enumerate(live)}
        if self.replan is not None and self.config.replan_lag is not None:
            for i, a in enumerate(live):
                if self._lag(a) > self.config.replan_lag:
                    self._replan(a, obs[i])
        self.t += 1
        self.stats.steps = self.t
        self.stats.waypoint_index = dict(self.index)
        return {a: actions[i] for i, a in enumerate(live)}

    def report_stuck(self, agents) -> None:
        """Count ``agents`` as stuck on their next step in which they are free to move (e.g. a safety
        layer between the controller and the env has kept them from moving as asked): they escape,
        and replan (or hand the leg over) as agents found stuck do."""
        self._reported.update(a for a in agents if a in self.plans)

    def set_plan(self, agent: str, plan: AgentPlan) -> None:
        """Give ``agent`` a new plan from now on (it starts at the plan's first waypoint)."""
        self.set_plans({agent: plan})

    def set_plans(self, plans: Dict[str, AgentPlan]) -> None:
        """Give several agents new plans at once (e.g. a joint replan, whose plan-order dependencies
        refer to each other); each starts at its plan's first waypoint."""
        unknown = sorted(set(plans) - set(self.plans))
        if unknown:
            raise KeyError(f"unknown agents {unknown}; agents are {sorted(self.plans)}")
        # new routes are not in the old plan's order: nobody waits on them any more
        for deps in self._after.values():
            for q in list(deps):
                deps[q] = [(b, r) for b, r in deps[q] if b not in plans]
        for agent, plan in plans.items():
            self.plans[agent] = plan
            self.index[agent] = 0
            self._after[agent] = {q: list(v) for q, v in (plan.after or {}).items()}
            self._blocked.pop(agent, None)
            self._gave_up[agent] = set()
            self._best.pop(agent, None)
            self._at_start[agent] = plan.starts_at_first and len(plan.waypoints) > 0
            self._thresholds[agent] = self._reach_thresholds(plan)
            self._progress.pop(agent, None)
            self._approach.pop(agent, None)
            self._back.pop(agent, None)
            self._stuck_count[agent] = 0
            self.stats.leg_escapes[agent] = 0

    def _replan(self, agent: str, obs: np.ndarray) -> None:
        assert self.replan is not None
        self.set_plan(agent, self.replan(agent, obs, self.plans[agent]))
        self.stats.replans += 1

    def _no_progress(self, agent: str, d: Optional[float], held: bool) -> bool:
        """Whether ``agent`` has come no closer (by a quarter step) to its current target for
        ``progress_patience`` steps in which it was free to move (``False`` when that rule is off)."""
        if self.config.progress_patience is None or d is None or not math.isfinite(d):
            return False
        k = self.index[agent]
        best = self._best.get(agent)
        if best is None or best[0] != k or d < best[1] - 0.25:
            self._best[agent] = (k, d, self.t)
        elif held:  # standing still on purpose does not count
            self._best[agent] = (k, best[1], self.t)
        elif self.t - best[2] >= self.config.progress_patience:
            self._best[agent] = (k, d, self.t)
            self.stats.stalls += 1
            return True
        return False

    def _activity(self, agent: str, reason: Optional[str], escaping: bool) -> str:
        """One of :data:`~agents.search.execution.stats.ACTIVITIES`: what ``agent`` does on this step (held
        for ``reason``)."""
        if reason is None:
            if escaping:
                return "escape"
            return "fallback" if self._fallback_at.get(agent) == self._reached[agent] else "drive"
        kind, _, other = reason.partition(":")
        if kind == "wait" and other:
            return "park" if self._parks_after.get(agent) == other else "order"
        return kind

    def _unstick(self, live: List[str], obs: np.ndarray, hold: np.ndarray, actions: np.ndarray,
                 to_target: Dict[str, float]) -> set:
        """Replace the actions of stuck agents free to move by random ones (edits ``actions``); returns
        the agents whose action it replaced."""
        scale = 255.0 if obs.dtype == np.uint8 else 1.0
        replaced = set()
        for i, a in enumerate(live):
            recent = self._recent[a]
            stalled = self._no_progress(a, to_target.get(a), bool(hold[i]))
            if a in self._reported and self._escape[a] == 0:
                self._reported.discard(a)
                stalled = True
            if hold[i]:  # standing still on purpose is not being stuck
                recent.clear()
                continue
            if self._escape[a] > 0:
                self._escape[a] -= 1
                actions[i] = self._escape_step(a, actions[i])
                replaced.add(a)
                recent.clear()
                continue
            recent.append(obs[i].astype(np.float32) / scale)
            if not stalled:
                if len(recent) < (recent.maxlen or 0):
                    continue
                if float(np.abs(recent[-1] - recent[0]).mean()) >= self.config.stuck_tolerance:
                    continue
            recent.clear()
            self.stats.escapes += 1
            self.stats.leg_escapes[a] = self.stats.leg_escapes.get(a, 0) + 1
            self._stuck_count[a] += 1
            self._stuck_total[a] = self._stuck_total.get(a, 0) + 1
            # escapes grow with each consecutive one on the way to the same target (up to 8x)
            self._escape[a] = self.config.escape_steps * 2 ** min(self._stuck_count[a] - 1, 3) - 1
            k = self.index[a]
            if self._stuck_count[a] >= self.config.skip_after:
                if self.fallback_policy is not None and self._fallback_at.get(a) != self._reached[a]:
                    self._fallback_at[a] = self._reached[a]  # hand this leg over first
                    self._go_back(a)
                    self._stuck_count[a] = 0
                    self.stats.fallbacks += 1
                elif self.replan is not None:  # the target seems out of reach from here: a new plan
                    self._replan(a, obs[i])
                elif k < len(self.plans[a].waypoints):  # no planner: head for the next target
                    self.index[a] = k + 1
                    self._stuck_count[a] = 0
                    self.stats.leg_escapes[a] = 0
                    self.stats.skips += 1
            self._escape_action.pop(a, None)
            if self._sidesteps(a):
                self._side[a] = -self._side[a]
            actions[i] = self._escape_step(a, actions[i])
            replaced.add(a)
        return replaced

    def _hand_over_far_legs(self, live: List[str], to_target: Dict[str, float]) -> None:
        """Hand a leg to ``fallback_policy`` from its start where the driver's critic puts its target
        beyond ``fallback_beyond`` (the graph's critic made it one edge: the driver will not go there)."""
        assert self.config.fallback_beyond is not None
        for a in live:
            plan, k = self.plans[a], self.index[a]
            d = to_target.get(a)
            read = self._leg_read.get(a)
            if a in self._back or d is None or read is not None and read[0] is plan and read[1] == k:
                continue
            self._leg_read[a] = (plan, k)
            if d > self.config.fallback_beyond and self._fallback_at.get(a) != self._reached[a]:
                self._fallback_at[a] = self._reached[a]
                self.stats.handovers += 1

    def _sidesteps(self, agent: str) -> bool:
        """Whether ``agent``'s escapes are sidesteps (see ``escape`` and ``sidestep_after``)."""
        if self.config.escape == "sidestep":
            return True
        return self.config.sidestep_after is not None and self._stuck_total.get(agent, 0) > self.config.sidestep_after

    def _escape_step(self, agent: str, action: np.ndarray) -> np.ndarray:
        """The escape action of ``agent`` now, given the action its policy would take (see ``escape``)."""
        if not self._sidesteps(agent):
            return self.rng.uniform(-1.0, 1.0, size=action.shape)
        step = self._escape_action.get(agent)
        if step is None:
            a = np.asarray(action, dtype=np.float64).reshape(-1)
            norm = float(np.hypot(a[0], a[1])) if a.size == 2 else 0.0
            if norm < 1e-3:  # no push to turn: a random direction
                a = self.rng.normal(size=2)
                norm = float(np.hypot(a[0], a[1])) or 1.0
            side = self._side[agent]
            step = np.array([-a[1] * side, a[0] * side]) / norm  # full speed
            self._escape_action[agent] = step
        return step.astype(np.asarray(action).dtype, copy=True)

    def _yield_mask(self, live: List[str], obs: np.ndarray, moving: np.ndarray,
                    to_target: Dict[str, float]) -> Dict[int, int]:
        """The agents (indices into ``live``) that yield on this step, each to the agent it yields to;
        only pairs of agents that would both move (``moving``) yield."""
        before, self._goal_priority = self._goal_priority, {}
        pushed, yielding, self._pushed, self._yielding = self._pushed, self._yielding, {}, {}
        assert self.config.safety_radius is not None  # checked by the caller
        both = moving[:, None] & moving[None, :]
        if self.bound is not None:  # the critic reads only pairs that may be close
            both &= self._lower_bound(obs, obs) < self.config.safety_radius
        ii, jj = np.nonzero(np.triu(both, 1))
        if len(ii) == 0:
            return {}
        close = pair_proximity(self.distance, self.proximity, obs[ii], obs[jj]) < self.config.safety_radius
        if not close.any():
            return {}
        lag = np.array([self._lag(a) for a in live])
        # the agent further behind its plan has priority; ties go to the lower index
        i_first = (lag[ii] > lag[jj]) | ((lag[ii] == lag[jj]) & (ii < jj))
        if self.config.goal_clearance is not None:
            i_first = self._goal_first(live, obs, ii, jj, close, i_first, before)
        if self.config.push_margin is not None:
            i_first = self._push_first(live, ii, jj, close, i_first, to_target, pushed, yielding)
        loser = np.where(i_first, jj, ii)[close]
        winner = np.where(i_first, ii, jj)[close]
        hold: Dict[int, int] = {}
        # process pairs in priority order so a yielding agent does not also block others
        for w, yielder in sorted(zip(winner.tolist(), loser.tolist())):
            if w not in hold and yielder not in hold:
                hold[yielder] = w
        self.stats.yields += len(hold)
        if self.config.push_margin is not None:
            self._note_yields(live, hold, to_target, yielding)
        return hold


__all__ = ["AgentPlan", "WaypointController"]
