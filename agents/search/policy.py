"""Search on the replay buffer as one policy object: plan with CBS, then follow the waypoints.

:class:`SearchPolicy` puts together what the paper's method is made of: a graph of buffer
observations annotated by a critic (:class:`~agents.search.planner.BufferPlanner`), CBS, and a
goal-conditioned policy that drives every agent from waypoint to waypoint
(:class:`~agents.search.controller.WaypointController`). It is used like a Stable-Baselines3
model::

    policy = SearchPolicy.from_models(critic, driver, c_max=0.25, safety=SafetyLayer.for_env(env))
    obs, infos = env.reset(seed=0)                # a PettingZoo parallel env ...
    while env.agents:
        actions, _ = policy.predict({a: obs[a] for a in env.agents}, positions=team_positions(env))
        obs, rewards, terminations, truncations, infos = env.step(actions)

and just as well on a single Gymnasium goal-conditioned observation (``obs, info =
env.reset()``; ``action, _ = policy.predict(obs)``). The first call of an episode plans for
every agent it is given (starts: their ``"observation"``, goals: their ``"desired_goal"``).
A new episode is recognised by :meth:`SearchPolicy.reset`, by ``episode_start``, by a changed
goal or by an agent that was not there on the previous call; call :meth:`reset` when an episode
repeats the previous one's problem exactly.

Only observations enter the planner and the controller; the optional
:class:`~agents.search.safety.SafetyLayer` reads the team's shared positions. This module does not
import torch; the models are only called through ``predict``, ``distance`` and ``pairwise``.
"""
from __future__ import annotations

import inspect
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ..run_folder import read_npz
from .controller import AgentPlan, WaypointController
from .dependencies import goal_passers, plan_dependencies, proximity_relation, shut_out
from .graph import NodePairwise, ProblemGraph, check_graph_nodes, env_record
from .models import (
    buffer_observations,
    check_models,
    default_controller_options,
    default_hold,
    default_reach_threshold,
    default_second_opinion,
    distance_fn,
    env_observations,
    policy_fn,
)
from .planner import BufferPlanner, MultiAgentPlan
from .repair import EdgeMemory
from .replanning import StuckReplanning
from .safety import SafetyLayer, SafetyState
from .stats import ControllerStats
from .waypoints import direct_plans


class UnknownOptionError(ValueError, TypeError):
    """Options that neither :class:`BufferPlanner` nor the policy takes (a ``ValueError``, and a
    ``TypeError`` as for an unknown keyword argument)."""


def planner_option_names() -> List[str]:
    """The options of :class:`BufferPlanner` (its keyword arguments besides nodes, matrices and critic)."""
    return sorted(set(inspect.signature(BufferPlanner.__init__).parameters)
                  - {"self", "observations", "D", "C", "pairwise"})


def _split_options(cls: type, options: Dict[str, Any]) -> Tuple[Dict[str, Any], Dict[str, Any]]:
    """``options`` split into those of :class:`BufferPlanner` and those of the policy class ``cls``;
    :class:`UnknownOptionError` names the unknown ones and lists the valid ones."""
    planner = set(planner_option_names())
    policy = set(inspect.signature(cls.__init__).parameters) - {"self", "planner", "policy_model"}  # type: ignore
    unknown = set(options) - planner - policy
    if unknown:
        raise UnknownOptionError(f"unknown options {sorted(unknown)}; planner options: {sorted(planner)}; "
                                 f"policy options: {sorted(policy)}")
    return {k: v for k, v in options.items() if k in planner}, {k: v for k, v in options.items() if k in policy}


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


class SearchPolicy(StuckReplanning):
    """Search on the replay buffer with CBS, driven by a goal-conditioned policy (``predict``).

    Args:
        planner: the buffer graph and its critic (see :meth:`from_models`); ``None`` drives
            every agent straight to its goal with the same controller rules (the plain
            policy).
        policy_model: the goal-conditioned model that drives the agents (``predict``); its
            critic (``distance``) decides when a waypoint is reached, unless ``distance_model``
            is given.
        distance_model: optional model whose ``distance`` replaces the driver's.
        budget: optional bound on each agent's total predicted route cost
            (:meth:`BufferPlanner.plan`).
        hold: how the agents keep to the plan. ``"order"``: in the plan's order, not on the
            clock: an agent sets off for a place the plan sends another agent through first only
            once that one has got far enough (:mod:`agents.search.dependencies`; an agent that is
            slower than planned delays the others instead of meeting them), and an agent parks at
            its goal only once the agents whose routes still pass it have gone by
            (:func:`~agents.search.dependencies.goal_passers`). ``"waits"`` (an early
            agent waits for its planned departure time where CBS made it wait) or ``"all"`` (at
            every waypoint): on the clock. Default :func:`default_hold` of the judging model:
            ``"order"`` for panorama agents, ``"waits"`` for vector ones.
        reach_threshold: a waypoint is reached at a predicted distance below this (steps);
            default :func:`default_reach_threshold` of the model that judges it.
        safety_radius: agents closer than this (predicted steps) yield to each other.
        replan_when_stuck: an agent stuck twice on the way to one waypoint gets a new single-agent
            plan from where it stands, around that waypoint and the nodes within ``ban_radius``
            predicted steps of it (a buffer graph has many nodes at almost the same place, and a
            critic that misjudged one edge misjudges their edges too), clear of agents parked at
            their goals, or localised; the edge it failed on is recorded in ``memory``. The steps:
            :mod:`agents.search.replanning`.
        ban_radius: see ``replan_when_stuck``.
        ban_detour: where keeping clear of the failed waypoint's neighbourhood makes a stuck agent's new
            route more than this many predicted steps longer than keeping clear of that waypoint alone,
            the replan keeps clear of the waypoint alone (a doorway holds several nodes, and the one
            the agent failed on may lie against the wall's end); ``inf`` (the default): never. Where
            the agent failed at a wormhole, the failed node's neighbours are look-alikes too, and
            a narrow replan sends it to the next one (see :mod:`agents.search.replanning`).
        repair_routes: an agent about to set off along an edge that another agent failed on in this
            episode (or that the memory removed meanwhile) plans anew from where it stands first (see
            :mod:`agents.search.replanning`); off by default: on the validation problems it saves
            little cost and loses runs (see the planning docs).
        detach_radius: where an agent set off for a node (or its goal) as one edge away and the
            critic now puts it far, the nodes within this many predicted steps of that node (of the
            node it set off from) are no longer linked to its start (its goal) in its replans of the
            episode (``None``: never); see :mod:`agents.search.replanning`.
        park_clearance: with ``hold="order"``, agents also park after those their goal would shut
            out (:func:`~agents.search.dependencies.shut_out`, this many predicted steps); ``None``: off.
        seed: seed of the controller's escape actions (each episode starts from it).
        deterministic: drive with the deterministic policy (default).
        fallback_model: optional second checkpoint that drives an agent's leg once the policy
            model is stuck on it (e.g. the unconstrained agent behind a constrained one that
            will not approach a goal beside furniture); see :class:`WaypointController`. Where the
            controller hands the legs its driver reads beyond ``fallback_beyond`` to it at once and
            the planner's ``second_opinion`` is the driver's critic, the planner plans no such leg (its
            ``max_leg``, unless set; ``inf`` keeps them).
        controller_kwargs: more options of :class:`WaypointController` (``stuck_window``,
            ``escape_steps``, ...), over :func:`default_controller_options` of the judging model.
        memory: the :class:`~agents.search.repair.EdgeMemory` of the graph (default: a new, empty
            one): every plan leaves out the edges it removed, and it learns from every episode
            unless frozen (``memory.frozen = True``; an evaluation learns on validation problems
            and freezes it for the test problems). :meth:`save` keeps it with the graph.
        safety: the :class:`~agents.search.safety.SafetyLayer` that filters every joint action so
            that no two agents touch (e.g. ``SafetyLayer.for_env(env)``); it reads the team's shared
            positions, which :meth:`predict` then needs (``positions=team_positions(env)``).
            ``None``: actions go to the env as the controller makes them.
    """

    def __init__(
        self,
        planner: Optional[BufferPlanner],
        policy_model: Any,
        distance_model: Any = None,
        *,
        budget: Optional[float] = None,
        hold: Optional[str] = None,
        reach_threshold: Optional[float] = None,
        safety_radius: Optional[float] = 2.0,
        replan_when_stuck: bool = True,
        ban_radius: float = 3.0,
        ban_detour: float = math.inf,
        repair_routes: bool = False,
        detach_radius: Optional[float] = 3.0,
        park_clearance: Optional[float] = None,
        seed: Optional[int] = 0,
        deterministic: bool = True,
        fallback_model: Any = None,
        controller_kwargs: Optional[Dict[str, Any]] = None,
        memory: Optional[EdgeMemory] = None,
        safety: Optional[SafetyLayer] = None,
    ) -> None:
        judge = distance_model if distance_model is not None else policy_model
        hold = default_hold(judge) if hold is None else hold
        if hold not in ("order", "all", "waits"):
            raise ValueError(f"hold must be 'order', 'all' or 'waits', got {hold!r}")
        if reach_threshold is None:
            reach_threshold = default_reach_threshold(judge)
        if not reach_threshold > 0:
            raise ValueError(f"reach_threshold must be > 0, got {reach_threshold!r}")
        if budget is not None and not budget > 0:
            raise ValueError(f"budget must be > 0 or None, got {budget!r}")
        if not hasattr(policy_model, "predict"):
            raise TypeError(f"the driving model needs a predict() method, got {type(policy_model).__name__}")
        if fallback_model is not None and not hasattr(fallback_model, "predict"):
            raise TypeError(f"the fallback model needs a predict() method, got {type(fallback_model).__name__}")
        if not hasattr(judge, "distance"):
            raise TypeError("the model that judges waypoints reached needs a distance() method")
        self.planner = planner
        self.policy_model = policy_model
        self.distance_model = judge
        self.budget = budget
        self.hold = hold
        self.reach_threshold = float(reach_threshold)
        self.safety_radius = safety_radius
        if safety is not None and not isinstance(safety, SafetyLayer):
            raise TypeError(f"safety must be a SafetyLayer or None, got {type(safety).__name__}")
        self.safety = safety
        self.replan_when_stuck = bool(replan_when_stuck)
        self.ban_radius = float(ban_radius)
        if not ban_detour >= 0:
            raise ValueError(f"ban_detour must be >= 0 (inf: never), got {ban_detour!r}")
        self.ban_detour = float(ban_detour)
        self.repair_routes = bool(repair_routes)
        if detach_radius is not None and not detach_radius >= 0:
            raise ValueError(f"detach_radius must be >= 0 or None, got {detach_radius!r}")
        self.detach_radius = detach_radius
        if park_clearance is not None and not park_clearance > 0:
            raise ValueError(f"park_clearance must be > 0 or None, got {park_clearance!r}")
        self.park_clearance = None if park_clearance is None else float(park_clearance)
        self.seed = seed
        self.deterministic = bool(deterministic)
        self.controller_kwargs = {**default_controller_options(judge), **(controller_kwargs or {})}
        beyond = self.controller_kwargs.get("fallback_beyond")
        if (planner is not None and fallback_model is not None and beyond is not None and planner.max_leg is None
                and getattr(planner.second_opinion, "model", None) is judge):
            self.planner = planner.with_options(max_leg=beyond)  # such a leg would go to the fallback at once
        self.fallback_model = fallback_model
        self._policy = policy_fn(policy_model, deterministic=self.deterministic)
        self._fallback = None if fallback_model is None else policy_fn(fallback_model, deterministic=self.deterministic)
        self._distance = distance_fn(self.distance_model)
        if memory is not None and planner is not None and memory.n_nodes != len(planner.observations):
            raise ValueError(f"the edge memory is of a graph of {memory.n_nodes} nodes, the planner's has "
                             f"{len(planner.observations)}")
        n_nodes = len(planner.observations) if planner is not None else 1
        #: edges agents failed to traverse, learned over episodes (see :mod:`agents.search.repair`)
        self.memory = memory if memory is not None else EdgeMemory(n_nodes)
        self.reset()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_models(
        cls,
        critic: Any,
        driver: Any = None,
        nodes: Union[np.ndarray, Any, None] = None,
        *,
        n_nodes: int = 1000,
        seed: int = 0,
        aggregate: str = "max",
        sparsify: Optional[float] = None,
        **options: Any,
    ) -> "SearchPolicy":
        """Build the graph with ``critic`` and drive with ``driver`` (default: the critic).

        Args:
            critic: the model whose ``pairwise`` distances and costs annotate the graph (the
                paper: the unconstrained agent).
            driver: the model that drives the agents (the paper: the constrained agent).
            nodes: the graph's node observations ``(N, ...)``, or a replay buffer to draw
                ``n_nodes`` of them from; ``None`` draws ``n_nodes`` random free states of the
                critic's environment (``critic.env_id``) and renders their observations.
            n_nodes: graph size when ``nodes`` is a replay buffer or ``None``.
            seed: seed of the node draw (and of the controller, unless ``options`` has one).
            aggregate: ensemble aggregation of the critic (``"max"``: pessimistic).
            sparsify: merge nodes the critic cannot tell apart, as starts and as goals, within
                this many steps (two-way consistency, :meth:`BufferPlanner.sparsified`); ``None``:
                keep every node.
            options: :class:`BufferPlanner` options (``d_max``, ``c_max``,
                ``proximity_radius``, ``suboptimality``, ``time_limit``, ...) and
                :class:`SearchPolicy` options (``budget``, ``hold``, ``reach_threshold``, ...).
        """
        check_models(critic, driver)
        planner_options, kwargs = _split_options(cls, options)
        if n_nodes < 2:
            raise ValueError(f"n_nodes must be >= 2, got {n_nodes}")
        if nodes is None:
            env_id = getattr(critic, "env_id", None)
            if not env_id:
                raise ValueError("the critic does not know its environment (env_id): pass nodes= (observations "
                                 "or a replay buffer)")
            obs = env_observations(env_id, n_nodes, seed)
        elif hasattr(nodes, "observations") and hasattr(nodes, "pos"):
            obs = buffer_observations(nodes, n_nodes, np.random.default_rng(seed))
        else:
            obs = np.asarray(nodes)
        planner_options.setdefault("second_opinion", default_second_opinion(critic, driver))
        planner = BufferPlanner.from_agent(critic, obs, aggregate=aggregate, **planner_options)
        if sparsify is not None:
            planner, _ = planner.sparsified(sparsify)
        kwargs.setdefault("seed", seed)
        return cls(planner, driver if driver is not None else critic, **kwargs)

    # ------------------------------------------------------------------ persistence
    def save(self, path: Union[str, Path]) -> Path:
        """Write the graph (node observations, ``D``, ``C``, the planner's options) and what it learned
        (:attr:`memory`) to ``path`` (``.npz``), with the environment of the critic that made ``D``
        and ``C`` and the shape of one observation; :meth:`load` reads it back with the models and
        checks them against this record."""
        if self.planner is None:
            raise ValueError("this SearchPolicy has no planner, hence no graph to save")
        p = self.planner
        path = Path(path)
        critic = getattr(p.pairwise, "model", None)
        env_id = next((getattr(m, "env_id", None) for m in (critic, self.distance_model, self.policy_model)
                       if getattr(m, "env_id", None)), None)
        arrays: Dict[str, Any] = dict(observations=p.observations, D=p.D, C=p.C,
                                      planner_options=np.array(json.dumps(p.options())), **self.memory.arrays())
        arrays.update(env_record(p.observations, env_id))
        np.savez_compressed(path, **arrays)
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    @classmethod
    def load(cls, path: Union[str, Path], critic: Any, driver: Any = None, *, aggregate: str = "max",
             **options: Any) -> "SearchPolicy":
        """A policy over the graph :meth:`save` wrote, with its edge memory.

        ``critic`` attaches start and goal observations to the graph (the model whose critics made
        ``D`` and ``C``), ``driver`` drives (default: the critic); ``options`` override saved planner
        options (``c_max``, ...) and set :class:`SearchPolicy` options, as in :meth:`from_models`.

        The file is read whole and checked: a missing, truncated or corrupt file, matrices that do
        not fit the nodes, saved planner options the planner does not take, node observations that
        are not finite or lie outside the critic's observation space, and a file made on another
        environment than the models' (files that record one) raise ``ValueError`` naming ``path``.
        """
        planner_options, kwargs = _split_options(cls, options)
        f = read_npz(path, "saved SearchPolicy graph")
        missing = [k for k in ("observations", "D", "C", "planner_options") if k not in f]
        if missing:
            raise ValueError(f"{path} is not a saved SearchPolicy graph: it lacks {missing}")
        obs, D, C = f["observations"], f["D"], f["C"]
        n = len(obs) if obs.ndim else -1
        for name, m in (("D", D), ("C", C)):
            if m.shape != (n, n) or m.dtype.kind not in "biuf":
                raise ValueError(f"{path}: {name} must be a ({n}, {n}) matrix of numbers for its {n} nodes, "
                                 f"got {m.shape} {m.dtype}")
            if not np.isfinite(m).all() or (m < 0).any():
                raise ValueError(f"{path}: {name} must be finite and non-negative")
        try:
            saved = json.loads(str(f["planner_options"]))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: its planner options are not JSON ({e})") from None
        if not isinstance(saved, dict):
            raise ValueError(f"{path}: its planner options are not a JSON object")
        unknown = sorted(set(saved) - set(planner_option_names()))
        if unknown:
            raise ValueError(f"{path}: its planner options {unknown} are not options of the planner; "
                             f"valid: {planner_option_names()}")
        try:
            memory = EdgeMemory.from_arrays(f)
        except ValueError as e:
            raise ValueError(f"{path} is not a saved SearchPolicy graph: {e}") from None
        if memory.n_nodes != len(obs):
            raise ValueError(f"{path}: its edge memory is of {memory.n_nodes} nodes, its graph has {len(obs)}")
        check_graph_nodes(path, f, obs, models=(critic, driver))
        planner_options.setdefault("second_opinion", default_second_opinion(critic, driver))
        if planner_options["second_opinion"] is None:
            saved.pop("max_leg", None)  # nothing to read legs with
        planner = BufferPlanner(obs, D, C, NodePairwise(critic, obs, aggregate), **{**saved, **planner_options})
        kwargs.setdefault("memory", memory)
        return cls(planner, driver if driver is not None else critic, **kwargs)

    # ------------------------------------------------------------------ episode state
    def reset(self, seed: Optional[int] = None) -> None:
        """Forget the current plan: the next :meth:`predict` plans anew (``seed`` replaces the
        controller's seed from now on)."""
        if seed is not None:
            self.seed = seed
        self.controller: Optional[WaypointController] = None
        #: the plan of the current episode (``None`` before the first call, or without a planner)
        self.current_plan: Optional[MultiAgentPlan] = None
        #: agent names in planning order
        self.agents: List[str] = []
        #: per agent, the node ids of its current route (the planner's problem graph)
        self.routes: Dict[str, List[int]] = {}
        #: per agent, the problem graph its route lives on, its goal's id there and the step it was planned at
        self._route_graph: Dict[str, Tuple[ProblemGraph, int, int]] = {}
        self._banned: Dict[str, List[int]] = {}
        #: per agent: the buffer edges it failed on this episode (left out of its replans)
        self._failed_edges: Dict[str, List[Tuple[int, int]]] = {}
        #: per agent: the buffer nodes its replans may not link its start to (it failed to reach them)
        self._detached: Dict[str, List[int]] = {}
        #: per agent: the buffer nodes its replans may not link to its goal (it failed to reach its goal from them)
        self._goal_detached: Dict[str, List[int]] = {}
        #: per agent: the waypoint index last seen, and whether its route changed since (for successes)
        self._seen_index: Dict[str, int] = {}
        #: per agent: the waypoint nodes it failed to reach since its last full plan
        self._failed: Dict[str, List[int]] = {}
        self._goals: Dict[str, np.ndarray] = {}
        self._last_obs: Dict[str, np.ndarray] = {}
        self._last_names: set = set()
        self._cut_cache: Dict[Tuple[int, ...], bool] = {}
        #: seconds spent on the episode's first plan, and on the replans since
        self.planning_time = 0.0
        self.replan_time = 0.0
        #: replans of the episode that kept clear of the failed waypoints alone (``ban_detour``)
        self.narrow_replans = 0
        #: replans of the episode before a leg along an edge another agent failed on (``repair_routes``)
        self.route_repairs = 0
        self._leg_checked: Dict[str, Tuple[AgentPlan, int]] = {}
        #: what the safety layer did in the episode
        self.safety_state = SafetyState()

    @property
    def stats(self) -> ControllerStats:
        """The controller's counters of the current episode (yields, waits, escapes, replans, ...)."""
        return self.controller.stats if self.controller is not None else ControllerStats()

    def waypoints(self, agent: str) -> np.ndarray:
        """The waypoint observations ``agent`` currently follows (its start first)."""
        if self.controller is None:
            raise ValueError("no plan yet: call predict() first")
        return self.controller.plans[agent].waypoints

    def leg(self, agent: str) -> Optional[Leg]:
        """The edge of its planned route ``agent`` is on now (``None`` without a planned route)."""
        if self.controller is None or self.planner is None or agent not in self._route_graph:
            return None
        route = self.routes.get(agent, [])
        problem, goal_id, started = self._route_graph[agent]
        k = self.controller.index[agent]
        target = route[k] if k < len(route) else goal_id
        source = route[k - 1] if k > 0 else None
        n = problem.n_buffer
        predicted = math.nan if source is None else float(problem.D[source, target])

        def buffer_id(i: Optional[int]) -> Optional[int]:
            return None if i is None or i >= n else int(i)

        return Leg(buffer_id(source), buffer_id(target), predicted, started)

    # ------------------------------------------------------------------ acting
    def predict(
        self,
        observation: Mapping[str, Any],
        state: Any = None,
        episode_start: Optional[Union[bool, np.ndarray]] = None,
        deterministic: Optional[bool] = None,
        positions: Optional[Mapping[str, Any]] = None,
    ) -> Tuple[Any, None]:
        """Actions for a goal-conditioned observation dict, or a dict agent -> observation dict.

        Returns ``(action, None)`` like an SB3 model: an action array for a single Gymnasium
        observation, a dict agent -> action for a PettingZoo parallel env's observations (pass
        the live agents', ``{a: obs[a] for a in env.agents}``: an agent that has just arrived
        still has an observation but needs no action). ``state`` is ignored; a true
        ``episode_start`` starts a new episode. ``deterministic`` must agree with the one the
        policy was made with, if given.

        ``positions``: the team's shared positions, agent name -> ``(x, y)`` in world units for
        every agent of the team, parked ones too (:func:`~agents.search.safety.team_positions`);
        required with a :attr:`safety` layer, which reads them to keep the agents apart, and
        read by nothing else (the planner and the controller see observations only).
        """
        if deterministic is not None and bool(deterministic) != self.deterministic:
            raise ValueError(f"this SearchPolicy drives with deterministic={self.deterministic}; "
                             "make another one to change it")
        single = isinstance(observation, Mapping) and "desired_goal" in observation
        obs_by_agent: Mapping[str, Any] = {"agent_0": observation} if single else observation
        if not isinstance(obs_by_agent, Mapping) or not obs_by_agent:
            raise TypeError("predict() takes a goal-conditioned observation dict (observation, achieved_goal, "
                            "desired_goal) or a non-empty dict from agent name to such a dict, got "
                            f"{type(observation).__name__}")
        current, goals = {}, {}
        for a, o in obs_by_agent.items():
            if not isinstance(o, Mapping) or "observation" not in o or "desired_goal" not in o:
                raise TypeError(f"observation of {a!r} must be a dict with 'observation' and 'desired_goal'")
            current[a] = self._one(np.asarray(o["observation"]), f"{a}: observation", single)
            goals[a] = self._one(np.asarray(o["desired_goal"]), f"{a}: desired_goal", single)
        if self._new_episode(current, goals, episode_start):
            self._start(current, goals)
        assert self.controller is not None
        self._last_obs.update(current)
        self._last_names = set(current)
        if self.repair_routes and self.planner is not None and self.replan_when_stuck:
            self._repair_routes(current)
        actions = self.controller.act(current)
        if self.safety is not None and not single:
            if positions is None:
                raise ValueError("this SearchPolicy has a safety layer: pass the team's positions, "
                                 "predict(obs, positions=team_positions(env))")
            actions = self.safety.filter_agents(actions, positions, self.safety_state)
            # kept from moving as asked for a while: stuck, as far as the plan goes
            self.controller.report_stuck(self.safety_state.deadlocked)
        self._record_progress()
        if single:
            act = actions["agent_0"]
            return (act[None] if np.ndim(observation["observation"]) > len(self._shape()) else act), None
        return actions, None

    def replan(self, agents: Optional[Sequence[str]] = None) -> MultiAgentPlan:
        """Plan again for ``agents`` (default: every agent seen on the last call) from their last
        observations, jointly with CBS; the others keep their plans. Returns the new plan (its
        ``status`` says whether it was solved; unsolved, the agents keep their plans)."""
        if self.controller is None or self.planner is None:
            raise ValueError("nothing to replan: " + ("no planner" if self.planner is None else "call predict() first"))
        names = list(agents) if agents is not None else [a for a in self.agents if a in self._last_names]
        unknown = [a for a in names if a not in self._last_obs]
        if unknown or not names:
            raise ValueError(f"cannot replan {unknown or names}: agents seen are {sorted(self._last_obs)}")
        t0 = time.perf_counter()
        plan = self._plan(np.stack([self._last_obs[a] for a in names]), np.stack([self._goals[a] for a in names]))
        if plan.solved:
            t = self.controller.t
            new = {}
            for i, (a, p) in enumerate(self._agent_plans(plan, names).items()):
                shifted = None if p.depart_times is None else [d + t if d > 0 else 0 for d in p.depart_times]
                new[a] = AgentPlan(p.waypoints, p.goal, shifted, p.starts_at_first, p.after)
                self.routes[a] = list(plan.nodes[i])
                assert plan.problem is not None  # a solved plan keeps its problem graph
                self._route_graph[a] = (plan.problem, plan.problem.goal_ids[i], t)
                self._banned[a] = []
                self._failed[a] = []
            self.controller.set_plans(new)
            self._seen_index.update({a: 0 for a in names})
        self.replan_time += time.perf_counter() - t0
        return plan

    # ------------------------------------------------------------------ internals
    def _shape(self) -> Tuple[int, ...]:
        if self.planner is not None:
            return tuple(self.planner.observations.shape[1:])
        return tuple(next(iter(self._goals.values())).shape) if self._goals else ()

    def _one(self, x: np.ndarray, what: str, single: bool) -> np.ndarray:
        """One agent's observation, checked against the graph's observation shape."""
        shape = self._shape()
        if shape and x.shape != shape:
            if single and x.shape == (1, *shape):  # a VecEnv with one environment
                return x[0]
            raise ValueError(f"{what} has shape {x.shape}, the graph's observations have shape {shape}"
                             + (" (SearchPolicy drives one environment, not a batch)" if x.shape[1:] == shape else ""))
        if x.dtype.kind == "f" and not np.isfinite(x).all():
            raise ValueError(f"{what} contains NaN or infinite values")
        return x

    def _new_episode(self, current: Dict[str, np.ndarray], goals: Dict[str, np.ndarray],
                     episode_start: Optional[Union[bool, np.ndarray]]) -> bool:
        if (self.controller is None or (episode_start is not None and bool(np.any(episode_start)))
                or any(a not in self._goals for a in current) or not set(current) <= self._last_names):
            return True
        return any(not np.array_equal(goals[a], self._goals[a]) for a in current)

    def _start(self, current: Dict[str, np.ndarray], goals: Dict[str, np.ndarray]) -> None:
        """Plan for every agent given and set up the controller."""
        self.reset()
        t0 = time.perf_counter()
        names = list(current)
        starts = np.stack([current[a] for a in names])
        goal_arr = np.stack([goals[a] for a in names])
        plans: Dict[str, AgentPlan]
        if self.planner is None:
            plans = direct_plans(goal_arr, names)
        else:
            plan = self._plan(starts, goal_arr)
            self.current_plan = plan
            plans = self._agent_plans(plan, names) if plan.solved else direct_plans(goal_arr, names)
            self.routes = {a: list(plan.nodes[i][:len(plans[a].waypoints)]) if plan.solved else []
                           for i, a in enumerate(names)}
            if plan.solved and plan.problem is not None:
                self._route_graph = {a: (plan.problem, plan.problem.goal_ids[i], 0) for i, a in enumerate(names)}
            self._banned = {a: [] for a in names}
            self._failed = {a: [] for a in names}
            self._failed_edges = {a: [] for a in names}
            self._detached = {a: [] for a in names}
            self._goal_detached = {a: [] for a in names}
            self._seen_index = {a: 0 for a in names}
        self.planning_time = time.perf_counter() - t0
        self.agents = names
        self._goals = dict(goals)
        replan = self._replan_stuck if self.planner is not None and self.replan_when_stuck else None
        goal_order = self._goal_blockers if self.hold == "order" and self.planner is not None else None
        self.controller = WaypointController(self._policy, self._distance, plans,
                                             reach_threshold=self.reach_threshold, safety_radius=self.safety_radius,
                                             seed=self.seed, replan=replan, fallback_policy=self._fallback,
                                             goal_order=goal_order, **self.controller_kwargs)

    def _plan(self, starts: np.ndarray, goals: np.ndarray) -> MultiAgentPlan:
        """A joint plan without the edges the memory removed; where that leaves an agent without any
        route (the removed edges were the only way), with them."""
        assert self.planner is not None
        removed = self.memory.removed()
        plan = self.planner.plan(starts, goals, budget=self.budget, exclude_edges=removed)
        if len(removed) and plan.status == "infeasible":
            plan = self.planner.plan(starts, goals, budget=self.budget)
        return plan

    def _agent_plans(self, plan: MultiAgentPlan, names: List[str]) -> Dict[str, AgentPlan]:
        """The controller's plans of a solved plan, kept by the clock or in the plan's order (``hold``)."""
        if self.hold != "order":
            return plan.agent_plans(names, hold=self.hold)
        plans = plan.agent_plans(names, hold="waits")
        radius = self.planner.proximity_radius if self.planner is not None else None
        problem = plan.problem
        if radius is None or problem is None or len(names) < 2:
            return {a: AgentPlan(p.waypoints, p.goal, None, p.starts_at_first) for a, p in plans.items()}
        close = proximity_relation(problem.D, radius, problem.n_buffer, problem.n_agents)
        deps = plan_dependencies(plan.nodes, plan.node_arrivals, plan.depart_times, problem.goal_ids,
                                 plan.arrival_times, close)
        return {a: AgentPlan(p.waypoints, p.goal, None, p.starts_at_first,
                             after={q: [(names[i], r) for i, r in v] for q, v in deps[j].items()})
                for j, (a, p) in enumerate(plans.items())}

    def _record_progress(self) -> None:
        """Record the buffer edges agents got through since the last step in :attr:`memory`."""
        assert self.controller is not None
        n = len(self.planner.observations) if self.planner is not None else 0
        for a, seen in self._seen_index.items():
            now = self._seen_index[a] = self.controller.index.get(a, seen)
            self.memory.record_route(self.routes.get(a, []), seen, now, n)

    def _goal_blockers(self, agent: str) -> List[Tuple[str, int]]:
        """The controller's ``goal_order``: :func:`~agents.search.dependencies.goal_passers` of
        ``agent`` on the routes as they are now, within the planner's proximity radius."""
        assert self.planner is not None and self.controller is not None
        if agent not in self._route_graph:
            return []
        others = {b: (self.routes.get(b, []), *self._route_graph[b][:2], self.controller.index.get(b, 0))
                  for b in self.agents if b != agent and b in self._route_graph}
        problem, goal, _ = self._route_graph[agent]
        out = goal_passers(problem, goal, others, float(self.planner.proximity_radius or 0.0))
        if self.park_clearance is not None:
            under_way = {b: v for b, v in others.items() if b in self._last_names and b not in dict(out)}
            out += shut_out(problem, goal, under_way, self.park_clearance, self._cut_cache)
        return out


__all__ = ["Leg", "SearchPolicy", "UnknownOptionError", "planner_option_names"]
