"""The compared methods of the 2D evaluation, and one execution of a method on a problem.

Every method runs the same shipped checkpoints on the same problems:

========================  ==============  =====================================================
method                    policy          plan
========================  ==============  =====================================================
``unconstrained_policy``  unconstrained   none: straight to the goal
``sorb``                  unconstrained   CBS on the distance-pruned buffer graph (SoRB + CBS)
``constrained_policy``    constrained     none: straight to the goal
``ours``                  constrained     CBS on the distance- and cost-pruned graph (the paper)
``ours_budget``           constrained     as ``ours``, routes first bounded by a risk budget
========================  ==============  =====================================================

The buffer graph is annotated by the *unconstrained* agent's critics (as in the paper);
execution uses the method's own policy and distance critic (closed-loop waypoint advance) and,
for every method, the same yield rule between agents.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Dict, List, Optional

import numpy as np

from agents.search.controller import AgentPlan, WaypointController
from agents.search.planner import BufferPlanner, direct_plans


@dataclass(frozen=True)
class Method:
    """A named, configurable method.

    Attributes:
        name: short key (CLI ``--methods``).
        label: column title in the table.
        policy: which checkpoint drives the agents: ``"unconstrained"`` or ``"constrained"``.
        search: plan waypoints with CBS on the buffer graph (``False``: straight to the goal).
        c_max: cost cut-off of the graph's edges (``inf``: distance pruning only).
        budget: optional per-agent bound on the total predicted cost of a route.
        hold: where an early agent waits for its planned departure time: ``"all"`` waypoints
            or only where the plan ``"waits"``.
    """

    name: str
    label: str
    policy: str
    search: bool
    c_max: float = math.inf
    budget: Optional[float] = None
    hold: str = "waits"

    def with_options(self, **kwargs) -> "Method":
        return replace(self, **kwargs)


#: edge cost cut-off of the constrained search (predicted cumulative cost of one edge)
DEFAULT_C_MAX = 0.25
#: risk budget of ``ours_budget`` (predicted cumulative cost of a whole route)
DEFAULT_BUDGET = 2.0

METHODS: Dict[str, Method] = {
    m.name: m
    for m in (
        Method("unconstrained_policy", "Unconstrained Policy", "unconstrained", False),
        Method("sorb", "Unconstrained Search (SoRB+CBS)", "unconstrained", True),
        Method("constrained_policy", "Constrained Policy", "constrained", False),
        Method("ours", "Constrained Search (Ours, CBS)", "constrained", True, c_max=DEFAULT_C_MAX),
        Method("ours_budget", "Constrained Search + Risk Budget", "constrained", True, c_max=DEFAULT_C_MAX,
               budget=DEFAULT_BUDGET),
    )
}

#: the four methods of the paper's Table I
PAPER_METHODS = ("unconstrained_policy", "sorb", "constrained_policy", "ours")


def get_methods(names) -> List[Method]:
    """Look methods up by name; unknown names raise ``ValueError`` listing the known ones."""
    out = []
    for n in names:
        if n not in METHODS:
            raise ValueError(f"unknown method {n!r}; known: {', '.join(METHODS)}")
        out.append(METHODS[n])
    return out


@dataclass
class Execution:
    """What happened when a method ran one problem (all arrays per agent)."""

    success: bool
    reached: np.ndarray
    cost: np.ndarray
    steps: int
    collisions: int  # contacts between two agents, each counted when it begins
    planning_time: float
    plan_status: str
    trajectories: np.ndarray  # (T + 1, K, 2) positions, for figures
    extra: Dict[str, Any] = field(default_factory=dict)


def policy_fn(model):
    """``policy(obs[B], goal[B]) -> actions[B, 2]`` from a goal-conditioned SB3 model (deterministic)."""

    def act(obs: np.ndarray, goals: np.ndarray) -> np.ndarray:
        batch = {"observation": obs, "achieved_goal": obs, "desired_goal": goals}
        return model.predict(batch, deterministic=True)[0]

    return act


def distance_fn(model):
    """``distance(obs[B], goal[B]) -> [B]`` predicted steps (pessimistic ensemble)."""

    def dist(obs: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return model.distance(obs, goals, aggregate="max")

    return dist


def execute(
    env,
    method: Method,
    models: Dict[str, Any],
    planner: Optional[BufferPlanner],
    starts: np.ndarray,
    goals: np.ndarray,
    seed: int = 0,
    reach_threshold: float = 2.0,
    safety_radius: float = 2.0,
    hold: Optional[str] = None,
    ban_radius: float = 3.0,
) -> Execution:
    """Run ``method`` from positions ``starts`` to ``goals`` in the parallel env ``env``.

    Positions only place the agents (the environment's reset); the planner and the agents
    see observations. The run ends when every agent is at its goal or at ``env.max_cycles``.
    ``hold`` overrides the method's (see :meth:`~agents.search.planner.MultiAgentPlan.agent_plans`).
    A search method's agent that gets stuck on the way to a waypoint (see
    :class:`~agents.search.controller.WaypointController`) gets a new single-agent plan from
    its current observation on the same graph, without the buffer nodes it failed to reach
    and those within ``ban_radius`` predicted steps of them (a buffer graph has many nodes at
    almost the same place, and the critic that misjudged one edge misjudges their edges too).
    """
    obs, infos = env.reset(seed=seed, options={"starts": starts, "goals": goals})
    names = list(env.agents)
    o = np.stack([obs[a]["observation"] for a in names])
    g = np.stack([obs[a]["desired_goal"] for a in names])
    model = models[method.policy]
    t0 = time.perf_counter()
    status = "direct"
    extra: Dict[str, Any] = {}
    replan = None
    if method.search:
        if planner is None:
            raise ValueError(f"method {method.name!r} needs a planner")
        p = planner.with_options(c_max=method.c_max) if planner.c_max != method.c_max else planner
        plan = p.plan(o, g, budget=method.budget)
        status = plan.status
        extra = {"c_max_used": plan.c_max, "soc": plan.soc, "waypoints": [len(x) for x in plan.nodes],
                 "predicted_cost": plan.predicted_cost, "nodes": plan.nodes}
        plans = plan.agent_plans(p.last_observations, g, names, hold=hold or method.hold) if plan.solved else direct_plans(g, names)
        routes = {a: list(plan.nodes[i][:len(plans[a].waypoints)]) if plan.solved else [] for i, a in enumerate(names)}
        banned: Dict[str, List[int]] = {a: [] for a in names}
        n_nodes = len(p.observations)
        extra["replan_time"] = 0.0

        def replan(agent: str, ob: np.ndarray, current: AgentPlan) -> AgentPlan:
            # called by the controller below (``ctrl``), which exists by the time an agent is stuck
            t1 = time.perf_counter()
            k = ctrl.index[agent]
            route = routes[agent]
            # the failed waypoint (on the last leg: the waypoint the goal was approached from) and
            # the nodes right by it
            f = route[k] if k < len(route) else (route[-1] if route else n_nodes)
            if f < n_nodes:
                near = np.minimum(p.D[f], p.D[:, f]) < ban_radius
                banned[agent].extend(np.flatnonzero(near).tolist() + [f])
            i = names.index(agent)
            sub = p.plan(ob[None], g[i:i + 1], budget=method.budget, exclude=banned[agent])
            if sub.solved:
                new = sub.agent_plans(p.last_observations, g[i:i + 1], [agent], hold="waits")[agent]
                routes[agent] = list(sub.nodes[0])
            else:  # no other way on the graph: give the waypoint up
                new = AgentPlan(current.waypoints[k + 1:], current.goal)
                routes[agent] = route[k + 1:]
            extra["replan_time"] += time.perf_counter() - t1
            return new
    else:
        plans = direct_plans(g, names)
    planning_time = time.perf_counter() - t0
    ctrl = WaypointController(policy_fn(model), distance_fn(model), plans, reach_threshold=reach_threshold,
                              safety_radius=safety_radius, seed=seed, replan=replan)
    k = len(names)
    index = {a: i for i, a in enumerate(names)}
    cost = np.zeros(k)
    reached = np.zeros(k, dtype=bool)
    collisions = 0
    touching: set = set()
    traj = [env.positions]
    steps = 0
    while env.agents:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        obs, _, term, trunc, infos = env.step(actions)
        steps += 1
        traj.append(env.positions)
        now = set()
        for a, info in infos.items():
            i = index[a]
            cost[i] += float(info.get("obstacle_cost", info["cost"]))
            now.update(frozenset((a, b)) for b in info.get("collided_with", ()))
            if term.get(a, False):
                reached[i] = True
        collisions += len(now - touching)  # a contact counts once, when it begins
        touching = now
    extra["yields"] = ctrl.stats.yields
    extra["waits"] = ctrl.stats.waits
    extra["escapes"] = ctrl.stats.escapes
    extra["skips"] = ctrl.stats.skips
    extra["replans"] = ctrl.stats.replans
    return Execution(bool(reached.all()), reached, cost, steps, collisions, planning_time, status,
                     np.stack(traj), extra)


__all__ = ["DEFAULT_BUDGET", "DEFAULT_C_MAX", "Execution", "METHODS", "Method", "PAPER_METHODS",
           "distance_fn", "execute", "get_methods", "policy_fn"]
