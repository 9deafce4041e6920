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
``ippo``                  IPPO (MARL)     none: the multi-agent RL policy alone (opt-in)
``mappo_lag``             MAPPO-Lag       none: the multi-agent RL policy alone (opt-in)
========================  ==============  =====================================================

The buffer graph is annotated by the *unconstrained* agent's critics (as in the paper);
execution uses the method's own policy and distance critic (closed-loop waypoint advance) and,
for every method, the same yield rule between agents.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from agents.search.config import SearchConfig, preset_for
from agents.search.execution.repair import EdgeMemory
from agents.search.execution.safety import SafetyLayer, team_positions
from agents.search.execution.stats import ACTIVITIES
from agents.search.planner import BufferPlanner
from agents.search.policy import SearchPolicy

from .anatomy import AgentFailure, FailureTracker
from .contact_anatomy import contact_reason
from .execution import Contacts, Execution, geodesic_of, tally_step


@dataclass(frozen=True)
class Method:
    """A named method: which checkpoint drives, whether it plans, and its change to the search config.

    Attributes:
        name: short key (CLI ``--methods``).
        label: column title in the table.
        policy: which checkpoint drives the agents: ``"unconstrained"`` or ``"constrained"``.
        search: plan waypoints on the buffer graph (``False``: straight to the goal).
        options: the method's change to the search config, as ``(option, value)`` pairs by the
            names of :data:`~agents.search.config.OPTIONS` (e.g. ``(("c_max", 0.25),)``); applied to
            the evaluation's config (the planner's graph and solver, the driver's preset for the
            rest) when the method runs.
        fallback: optional second checkpoint (``"unconstrained"``) that takes over an agent's
            leg once its own policy is stuck there (see
            :class:`~agents.search.execution.controller.WaypointController`).
        safety: run with the :class:`~agents.search.execution.safety.SafetyLayer` of the env between the
            controller and the env (the agents share their positions within the team).
    """

    name: str
    label: str
    policy: str
    search: bool
    options: Tuple[Tuple[str, Any], ...] = ()
    fallback: Optional[str] = None
    safety: bool = True

    def __post_init__(self) -> None:
        SearchConfig().updated(**dict(self.options))  # unknown names and bad values fail here

    def with_options(self, **kwargs: Any) -> "Method":
        """The method with config options (by name) or its ``fallback`` / ``safety`` changed."""
        own = {k: kwargs.pop(k) for k in ("fallback", "safety") if k in kwargs}
        return replace(self, options=tuple({**dict(self.options), **kwargs}.items()), **own)

    def option(self, name: str, default: Any = None) -> Any:
        """The value the method gives the config option ``name`` (``default`` where it gives none)."""
        return dict(self.options).get(name, default)

    @property
    def c_max(self) -> float:
        """The method's edge cost cut-off (``inf``: distance pruning only)."""
        return float(self.option("c_max", math.inf))

    @property
    def budget(self) -> Optional[float]:
        """The method's risk budget (``None``: none)."""
        return self.option("budget")

    def config(self, base: SearchConfig) -> SearchConfig:
        """``base`` with the method's options applied."""
        return base.updated(**dict(self.options)) if self.options else base


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
        Method("ours", "Constrained Search (Ours, CBS)", "constrained", True, (("c_max", DEFAULT_C_MAX),)),
        Method("ours_budget", "Constrained Search + Risk Budget", "constrained", True,
               (("c_max", DEFAULT_C_MAX), ("budget", DEFAULT_BUDGET))),
        # the multi-agent RL baselines (baselines.marl_rows): their policy is the model of the same name
        Method("ippo", "IPPO (MARL)", "ippo", False),
        Method("mappo_lag", "MAPPO-Lagrangian (MARL)", "mappo_lag", False),
    )
}

#: the methods that run their own multi-agent RL policy (``safe-mapf train-marl``)
MARL_METHODS = ("ippo", "mappo_lag")
#: what ``safe-mapf evaluate`` runs without ``--methods``: every method but the MARL ones
DEFAULT_METHODS = tuple(m for m in METHODS if m not in MARL_METHODS)

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


def execute(
    env,
    method: Method,
    models: Dict[str, Any],
    planner: Optional[BufferPlanner],
    starts: np.ndarray,
    goals: np.ndarray,
    seed: int = 0,
    node_positions: Optional[np.ndarray] = None,
    memory: Optional[EdgeMemory] = None,
) -> Execution:
    """Run ``method`` from positions ``starts`` to ``goals`` in the parallel env ``env``.

    Positions only place the agents (the environment's reset); the planner and the agents
    see observations. The run ends when every agent is at its goal or at ``env.max_cycles``.
    Every method runs as a :class:`~agents.search.policy.SearchPolicy` (without a planner for
    the methods without search) whose config is the planner's graph and solver with the
    driver's preset (:func:`~agents.search.config.preset_for`) for the rest, changed by the
    method's options (:meth:`Method.config`).

    Every agent that does not arrive gets a reason (:attr:`Execution.failures`, see
    :mod:`baselines.anatomy`), read from ground truth after the run; ``node_positions`` (the
    buffer nodes' true positions, for evaluation only) adds the true length of the leg it was on.

    ``memory`` is the search's :class:`~agents.search.execution.repair.EdgeMemory` (default: a new one,
    returned in ``extra["memory"]`` with what this run taught it).
    """
    if method.policy in MARL_METHODS:
        from .marl_rows import execute_marl

        return execute_marl(env, models[method.policy], starts, goals, seed=seed)
    obs, infos = env.reset(seed=seed, options={"starts": starts, "goals": goals})
    names = list(env.agents)
    driver = models[method.policy]
    base = preset_for(driver)
    if method.search:
        if planner is None:
            raise ValueError(f"method {method.name!r} needs a planner")
        base = replace(base, graph=planner.graph, solver=planner.solver_config)
    safety = SafetyLayer.for_env(env) if method.safety and getattr(env, "agent_collisions", True) else None
    config = method.config(base)
    if method.search:
        assert planner is not None
        planner = planner.with_configs(config.graph, config.solver)
    policy = SearchPolicy(planner if method.search else None, driver, controller=config.controller,
                          replanning=config.replanning, budget=config.budget, seed=seed,
                          fallback_model=models[method.fallback] if method.fallback else None,
                          memory=memory if method.search else None, safety=safety,
                          bound=env.step_bound() if env.obs_type == "vector" else None)
    k = len(names)
    index = {a: i for i, a in enumerate(names)}
    cost = np.zeros(k)
    reached = np.zeros(k, dtype=bool)
    contacts = Contacts(index)
    traj = [env.positions]
    steps = 0
    step_length = float(getattr(env, "action_scale", 1.0))
    tracker = FailureTracker(names, step_length, touch=2.0 * env.scenario.agent_radius + 0.5 * step_length)
    parked_at = np.full(k, -1)
    split = np.zeros((k, len(ACTIVITIES)))
    goal_arr = np.asarray(goals, dtype=np.float64)
    activity: Dict[str, str] = {}

    def why(a: str, b: str) -> str:  # the reason of a contact that begins on this step
        i, j = index[a], index[b]
        return contact_reason(
            parked=[0 <= parked_at[n] < steps for n in (i, j)],
            goals_close=bool(np.linalg.norm(goal_arr[i] - goal_arr[j]) < tracker.touch),
            activities=[activity.get(a), activity.get(b)],
            holding=[policy.stats.holding.get(x) is not None for x in (a, b)])

    while env.agents:
        team = team_positions(env) if safety is not None else None
        actions, _ = policy.predict({a: obs[a] for a in env.agents}, positions=team)
        activity = dict(policy.stats.activity)
        obs, _, term, trunc, infos = env.step(actions)
        steps += 1
        traj.append(env.positions)
        tracker.step(policy.stats.holding, infos, env.agents)
        contacts.update(tally_step(infos, term, index, cost, reached, parked_at, steps, activity, split), why)
    plan = policy.current_plan
    extra: Dict[str, Any] = {}
    if plan is not None:
        extra = {"c_max_used": plan.c_max, "soc": plan.soc, "waypoints": [len(x) for x in plan.nodes],
                 "predicted_cost": plan.predicted_cost, "nodes": plan.nodes, "replan_time": policy.replan_time}
    stats = policy.stats
    extra.update(yields=stats.yields, waits=stats.waits, escapes=stats.escapes, skips=stats.skips,
                 replans=stats.replans, route_repairs=policy.route_repairs,
                 shield_steered=policy.safety_state.steered, shield_stopped=policy.safety_state.stopped)
    if method.search:
        extra["memory"] = policy.memory
    trajectories = np.stack(traj)
    failures: List[AgentFailure] = []
    if not reached.all():
        failures = tracker.diagnose(
            trajectories, np.asarray(goals, dtype=np.float64), reached, parked_at, geodesic_of(env),
            planned=plan is None or plan.solved, legs={a: policy.leg(a) for a in names},
            escapes=stats.leg_escapes, node_positions=node_positions)
    return Execution(bool(reached.all()), reached, cost, steps, contacts.count, policy.planning_time,
                     plan.status if plan is not None else "direct", trajectories, extra, failures, parked_at, split,
                     contacts.touched, contacts.reasons)


__all__ = ["DEFAULT_BUDGET", "DEFAULT_C_MAX", "DEFAULT_METHODS", "MARL_METHODS", "METHODS", "Method", "PAPER_METHODS",
           "execute", "get_methods"]
