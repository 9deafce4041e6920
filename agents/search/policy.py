"""Search on the replay buffer as one policy object: plan with CBS, then follow the waypoints.

:class:`SearchPolicy` puts together what the paper's method is made of: a graph of buffer
observations annotated by a critic (:class:`~agents.search.planner.BufferPlanner`), CBS, and a
goal-conditioned policy that drives every agent from waypoint to waypoint
(:class:`~agents.search.execution.controller.WaypointController`). It is used like a Stable-Baselines3
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
:class:`~agents.search.execution.safety.SafetyLayer` reads the team's shared positions. This module does not
import torch; the models are only called through ``predict``, ``distance`` and ``pairwise``.
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ..run_folder import read_npz
from .config import OPTIONS, ControllerConfig, ReplanConfig, SearchConfig, preset_for
from .execution.controller import AgentPlan, WaypointController
from .execution.dependencies import goal_passers, plan_dependencies, proximity_relation, shut_out
from .execution.episode import AgentState, Episode, Leg
from .execution.repair import EdgeMemory
from .execution.replanning import Replanner
from .execution.safety import SafetyLayer, SafetyState
from .execution.stats import ControllerStats
from .graph.build import NodePairwise, check_graph_nodes, env_record
from .models import buffer_observations, check_models, default_second_opinion, distance_fn, env_observations, policy_fn
from .planner import BufferPlanner, MultiAgentPlan
from .waypoints import direct_plans

#: :meth:`SearchPolicy.from_models`' and :meth:`SearchPolicy.load`'s marker of an argument not given
_DEFAULT: Any = object()
#: keyword arguments of :class:`SearchPolicy` that ``from_models`` and ``load`` pass on (not config options)
_POLICY_ARGUMENTS = ("distance_model", "deterministic", "fallback_model", "memory", "safety", "bound")


def _saved_config(path: Union[str, Path], text: Any, key: str) -> SearchConfig:
    """The graph and solver configs a saved graph file holds under ``key`` (JSON: the nested configs,
    or, under ``planner_options``, the planner's options by name); errors name ``path``."""
    try:
        data = json.loads(str(text))
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: its {key} are not JSON ({e})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: its {key} are not a JSON object")
    if key == "planner_config":
        extra = sorted(set(data) - {"graph", "solver"})
        if extra:
            raise ValueError(f"{path}: its planner config has parts {extra}; a planner has 'graph' and 'solver'")
        return SearchConfig.from_dict(data, where=str(path))
    planner = sorted(k for k, (part, _) in OPTIONS.items() if part in ("graph", "solver"))
    unknown = sorted(set(data) - set(planner))
    if unknown:
        raise ValueError(f"{path}: its planner options {unknown} are not options of the planner; valid: {planner}")
    try:
        return SearchConfig().updated(**data)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


class SearchPolicy:
    """Search on the replay buffer with CBS, driven by a goal-conditioned policy (``predict``).

    Args:
        planner: the buffer graph and its critic (see :meth:`from_models`); ``None`` drives
            every agent straight to its goal with the same controller rules (the plain
            policy).
        policy_model: the goal-conditioned model that drives the agents (``predict``); its
            critic (``distance``) decides when a waypoint is reached, unless ``distance_model``
            is given.
        distance_model: optional model whose ``distance`` replaces the driver's.
        controller: how the agents follow their plans (:class:`~agents.search.config.ControllerConfig`);
            ``None``: that of :func:`~agents.search.config.preset_for` the model that judges waypoints
            (``"panorama"`` or ``"vector"``).
        replanning: what a stuck agent's new plan keeps clear of
            (:class:`~agents.search.config.ReplanConfig`; ``None``: the defaults).
        budget: optional bound on each agent's total predicted route cost
            (:meth:`BufferPlanner.plan`).
        seed: seed of the controller's escape actions (each episode starts from it).
        deterministic: drive with the deterministic policy (default).
        fallback_model: optional second checkpoint that drives an agent's leg once the policy
            model is stuck on it (e.g. the unconstrained agent behind a constrained one that
            will not approach a goal beside furniture); see :class:`WaypointController`. Where the
            controller hands the legs its driver reads beyond ``fallback_beyond`` to it at once and
            the planner's ``second_opinion`` is the driver's critic, the planner plans no such leg (its
            ``max_leg``, unless set; ``inf`` keeps them).
        memory: the :class:`~agents.search.execution.repair.EdgeMemory` of the graph (default: a new, empty
            one): every plan leaves out the edges it removed, and it learns from every episode
            unless frozen (``memory.frozen = True``; an evaluation learns on validation problems
            and freezes it for the test problems). :meth:`save` keeps it with the graph.
        safety: the :class:`~agents.search.execution.safety.SafetyLayer` that filters every joint action so
            that no two agents touch (e.g. ``SafetyLayer.for_env(env)``); it reads the team's shared
            positions, which :meth:`predict` then needs (``positions=team_positions(env)``).
            ``None``: actions go to the env as the controller makes them.
        bound: optional ``bound(obs_a, obs_b) -> (N, M)``, a lower bound of the steps between
            observations that costs no critic call, such as the environment's ``min_steps``
            (vector observations): the controller's yield and clear-goal rules then read the
            critic only on pairs of agents it puts within their radii (with hundreds of agents,
            most pairs are far apart). ``None``: every pair is read.

    How the agents keep to the plan is the controller config's ``hold``: ``"order"`` (the plan's
    order, not its clock: an agent sets off for a place the plan sends another agent through first
    only once that one has got far enough, :mod:`agents.search.execution.dependencies`, and parks at its goal
    only once the agents whose routes still pass it have gone by,
    :func:`~agents.search.execution.dependencies.goal_passers`), ``"waits"`` or ``"all"`` (on the clock).
    A stuck agent's replan (the ``replanning`` part) is described in :mod:`agents.search.execution.replanning`.
    """

    def __init__(
        self,
        planner: Optional[BufferPlanner],
        policy_model: Any,
        distance_model: Any = None,
        controller: Optional[ControllerConfig] = None,
        replanning: Optional[ReplanConfig] = None,
        budget: Optional[float] = None,
        *,
        seed: Optional[int] = 0,
        deterministic: bool = True,
        fallback_model: Any = None,
        memory: Optional[EdgeMemory] = None,
        safety: Optional[SafetyLayer] = None,
        bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
    ) -> None:
        judge = distance_model if distance_model is not None else policy_model
        if not hasattr(policy_model, "predict"):
            raise TypeError(f"the driving model needs a predict() method, got {type(policy_model).__name__}")
        if fallback_model is not None and not hasattr(fallback_model, "predict"):
            raise TypeError(f"the fallback model needs a predict() method, got {type(fallback_model).__name__}")
        if not hasattr(judge, "distance"):
            raise TypeError("the model that judges waypoints reached needs a distance() method")
        controller = preset_for(judge).controller if controller is None else controller
        replanning = ReplanConfig() if replanning is None else replanning
        for name, value, cls in (("controller", controller, ControllerConfig),
                                 ("replanning", replanning, ReplanConfig)):
            if not isinstance(value, cls):
                raise TypeError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")
        config = SearchConfig(controller=controller, replanning=replanning, budget=budget)
        beyond = config.controller.fallback_beyond
        if (planner is not None and fallback_model is not None and beyond is not None
                and planner.graph.max_leg is None and getattr(planner.second_opinion, "model", None) is judge):
            planner = planner.with_options(max_leg=beyond)  # such a leg would go to the fallback at once
        self.planner = planner
        #: the settings in use (the planner's graph and solver, the controller, replanning, the budget)
        self.config = config if planner is None else replace(config, graph=planner.graph, solver=planner.solver_config)
        self.policy_model = policy_model
        self.distance_model = judge
        if safety is not None and not isinstance(safety, SafetyLayer):
            raise TypeError(f"safety must be a SafetyLayer or None, got {type(safety).__name__}")
        self.safety = safety
        if bound is not None and not callable(bound):
            raise TypeError(f"bound must be a function bound(obs_a, obs_b) or None, got {type(bound).__name__}")
        self.bound = bound
        self.seed = seed
        self.deterministic = bool(deterministic)
        self.fallback_model = fallback_model
        self._policy = policy_fn(policy_model, deterministic=self.deterministic)
        self._fallback = None if fallback_model is None else policy_fn(fallback_model, deterministic=self.deterministic)
        self._distance = distance_fn(self.distance_model)
        if memory is not None and planner is not None and memory.n_nodes != len(planner.observations):
            raise ValueError(f"the edge memory is of a graph of {memory.n_nodes} nodes, the planner's has "
                             f"{len(planner.observations)}")
        n_nodes = len(planner.observations) if planner is not None else 1
        #: edges agents failed to traverse, learned over episodes (see :mod:`agents.search.execution.repair`)
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
        config: Optional[SearchConfig] = None,
        second_opinion: Any = _DEFAULT,
        **kwargs: Any,
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
            seed: seed of the node draw and of the controller.
            aggregate: ensemble aggregation of the critic (``"max"``: pessimistic).
            sparsify: merge nodes the critic cannot tell apart, as starts and as goals, within
                this many steps (two-way consistency, :meth:`BufferPlanner.sparsified`); ``None``:
                keep every node.
            config: the settings (default: :func:`~agents.search.config.preset_for` the driver).
            second_opinion: the planner's second critic (default:
                :func:`~agents.search.models.default_second_opinion` of the two models).
            kwargs: options of the config by name (:data:`~agents.search.config.OPTIONS`: ``c_max``,
                ``hold``, ``solver``, ...), applied to ``config``, and the constructor's keyword
                arguments (``fallback_model``, ``safety``, ``memory``, ``deterministic``,
                ``distance_model``, ``bound``; a ``bound`` also spares the planner's critic the
                pairs it rules out, as in :meth:`BufferPlanner.from_agent`). :attr:`config` of the
                result is the config in use.
        """
        check_models(critic, driver)
        own = {k: kwargs.pop(k) for k in _POLICY_ARGUMENTS if k in kwargs}
        judge = own.get("distance_model") or driver or critic
        config = (preset_for(judge) if config is None else config).updated(**kwargs)
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
        opinion = default_second_opinion(critic, driver) if second_opinion is _DEFAULT else second_opinion
        planner = BufferPlanner.from_agent(critic, obs, aggregate=aggregate, graph=config.graph, solver=config.solver,
                                           second_opinion=opinion, bound=own.get("bound"))
        if sparsify is not None:
            planner, _ = planner.sparsified(sparsify)
        own.setdefault("seed", seed)
        return cls(planner, driver if driver is not None else critic, controller=config.controller,
                   replanning=config.replanning, budget=config.budget, **own)

    # ------------------------------------------------------------------ persistence
    def save(self, path: Union[str, Path]) -> Path:
        """Write the graph (node observations, ``D``, ``C``, the planner's graph and solver configs)
        and what it learned (:attr:`memory`) to ``path`` (``.npz``), with the environment of the
        critic that made ``D`` and ``C`` and the shape of one observation; :meth:`load` reads it
        back with the models and checks them against this record. The configs are JSON: loading
        a file runs no code from it."""
        if self.planner is None:
            raise ValueError("this SearchPolicy has no planner, hence no graph to save")
        p = self.planner
        path = Path(path)
        critic = getattr(p.pairwise, "model", None)
        env_id = next((getattr(m, "env_id", None) for m in (critic, self.distance_model, self.policy_model)
                       if getattr(m, "env_id", None)), None)
        arrays: Dict[str, Any] = dict(observations=p.observations, D=p.D, C=p.C,
                                      planner_config=np.array(json.dumps(p.config())), **self.memory.arrays())
        arrays.update(env_record(p.observations, env_id))
        np.savez_compressed(path, **arrays)
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    @classmethod
    def load(cls, path: Union[str, Path], critic: Any, driver: Any = None, *, aggregate: str = "max",
             config: Optional[SearchConfig] = None, second_opinion: Any = _DEFAULT,
             **kwargs: Any) -> "SearchPolicy":
        """A policy over the graph :meth:`save` wrote, with its edge memory.

        ``critic`` attaches start and goal observations to the graph (the model whose critics made
        ``D`` and ``C``), ``driver`` drives (default: the critic). The settings are the file's graph
        and solver configs with the controller and replanning of
        :func:`~agents.search.config.preset_for` the driver, or ``config`` whole where given;
        ``kwargs`` change options of them by name and set the constructor's keyword arguments, as in
        :meth:`from_models`.

        The file is read whole and checked: a missing, truncated or corrupt file, matrices that do
        not fit the nodes, saved configs with fields the planner does not have, node observations
        that are not finite or lie outside the critic's observation space, and a file made on
        another environment than the models' (files that record one) raise ``ValueError`` naming
        ``path``.
        """
        own = {k: kwargs.pop(k) for k in _POLICY_ARGUMENTS if k in kwargs}
        f = read_npz(path, "saved SearchPolicy graph")
        settings = "planner_config" if "planner_config" in f else "planner_options"
        missing = [k for k in ("observations", "D", "C", settings) if k not in f]
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
        saved = _saved_config(path, f[settings], settings)
        try:
            memory = EdgeMemory.from_arrays(f)
        except ValueError as e:
            raise ValueError(f"{path} is not a saved SearchPolicy graph: {e}") from None
        if memory.n_nodes != len(obs):
            raise ValueError(f"{path}: its edge memory is of {memory.n_nodes} nodes, its graph has {len(obs)}")
        check_graph_nodes(path, f, obs, models=(critic, driver))
        judge = own.get("distance_model") or driver or critic
        if config is None:
            config = replace(preset_for(judge), graph=saved.graph, solver=saved.solver)
        opinion = default_second_opinion(critic, driver) if second_opinion is _DEFAULT else second_opinion
        if opinion is None and saved.graph.max_leg is not None and config.graph is saved.graph:
            config = replace(config, graph=replace(config.graph, max_leg=None))  # nothing to read legs with
        config = config.updated(**kwargs)
        planner = BufferPlanner(obs, D, C, NodePairwise(critic, obs, aggregate, bound=own.get("bound")),
                                config.graph, config.solver,
                                second_opinion=opinion)
        own.setdefault("memory", memory)
        return cls(planner, driver if driver is not None else critic, controller=config.controller,
                   replanning=config.replanning, budget=config.budget, **own)

    # ------------------------------------------------------------------ episode state
    def reset(self, seed: Optional[int] = None) -> None:
        """Forget the current plan: the next :meth:`predict` plans anew (``seed`` replaces the
        controller's seed from now on)."""
        if seed is not None:
            self.seed = seed
        self.controller: Optional[WaypointController] = None
        #: the plan of the current episode (``None`` before the first call, or without a planner)
        self.current_plan: Optional[MultiAgentPlan] = None
        #: what the policy knows of the current episode, one record per agent
        self.episode = Episode()
        self.replanner: Optional[Replanner] = None

    @property
    def agents(self) -> List[str]:
        """Agent names of the episode in planning order."""
        return self.episode.agents

    @property
    def routes(self) -> Dict[str, List[int]]:
        """Per agent, the node ids of its current route (the planner's problem graph)."""
        return {a: st.route for a, st in self.episode.states.items() if self.planner is not None}

    @property
    def planning_time(self) -> float:
        """Seconds spent on the episode's first plan."""
        return self.episode.planning_time

    @property
    def replan_time(self) -> float:
        """Seconds spent on the episode's replans."""
        return self.episode.replan_time

    @property
    def narrow_replans(self) -> int:
        """Replans of the episode that kept clear of the failed waypoints alone (``ban_detour``)."""
        return self.episode.narrow_replans

    @property
    def route_repairs(self) -> int:
        """Replans of the episode before a leg along an edge another agent failed on (``repair_routes``)."""
        return self.episode.route_repairs

    @property
    def safety_state(self) -> SafetyState:
        """What the safety layer did in the episode."""
        return self.episode.safety

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
        state = self.episode.states.get(agent)
        if self.controller is None or self.planner is None or state is None:
            return None
        return state.leg(self.controller.index[agent])

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
        every agent of the team, parked ones too (:func:`~agents.search.execution.safety.team_positions`);
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
        for a, o in current.items():
            self.episode.states[a].last_obs = o
        self.episode.live = set(current)
        replanning = self.config.replanning
        if replanning.repair_routes and self.replanner is not None and replanning.replan_when_stuck:
            self.replanner.repair_routes(self.controller, current)
        actions = self.controller.act(current)
        if self.safety is not None and not single:
            if positions is None:
                raise ValueError("this SearchPolicy has a safety layer: pass the team's positions, "
                                 "predict(obs, positions=team_positions(env))")
            actions = self.safety.filter_agents(actions, positions, self.episode.safety)
            # kept from moving as asked for a while: stuck, as far as the plan goes
            self.controller.report_stuck(self.episode.safety.deadlocked)
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
        ep = self.episode
        names = list(agents) if agents is not None else [a for a in ep.agents if a in ep.live]
        unknown = [a for a in names if a not in ep.states or ep.states[a].last_obs is None]
        if unknown or not names:
            seen = sorted(a for a, st in ep.states.items() if st.last_obs is not None)
            raise ValueError(f"cannot replan {unknown or names}: agents seen are {seen}")
        t0 = time.perf_counter()
        starts = [ep.states[a].last_obs for a in names]
        plan = self._plan(np.stack([o for o in starts if o is not None]), np.stack([ep.states[a].goal for a in names]))
        if plan.solved:
            t = self.controller.t
            new = {}
            for i, (a, p) in enumerate(self._agent_plans(plan, names).items()):
                shifted = None if p.depart_times is None else [d + t if d > 0 else 0 for d in p.depart_times]
                new[a] = AgentPlan(p.waypoints, p.goal, shifted, p.starts_at_first, p.after)
                assert plan.problem is not None  # a solved plan keeps its problem graph
                state = ep.states[a]
                state.set_route(plan.nodes[i], plan.problem, plan.problem.goal_ids[i], t)
                state.banned, state.failed = [], []
            self.controller.set_plans(new)
        ep.replan_time += time.perf_counter() - t0
        return plan

    # ------------------------------------------------------------------ internals
    def _shape(self) -> Tuple[int, ...]:
        if self.planner is not None:
            return tuple(self.planner.observations.shape[1:])
        states = self.episode.states
        return tuple(next(iter(states.values())).goal.shape) if states else ()

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
        states = self.episode.states
        if (self.controller is None or (episode_start is not None and bool(np.any(episode_start)))
                or any(a not in states for a in current) or not set(current) <= self.episode.live):
            return True
        return any(not np.array_equal(goals[a], states[a].goal) for a in current)

    def _start(self, current: Dict[str, np.ndarray], goals: Dict[str, np.ndarray]) -> None:
        """Plan for every agent given and set up the controller."""
        self.reset()
        t0 = time.perf_counter()
        names = list(current)
        ep = self.episode
        ep.states = {a: AgentState(goal=goals[a]) for a in names}
        starts = np.stack([current[a] for a in names])
        goal_arr = np.stack([goals[a] for a in names])
        plans: Dict[str, AgentPlan]
        if self.planner is None:
            plans = direct_plans(goal_arr, names)
        else:
            plan = self._plan(starts, goal_arr)
            self.current_plan = plan
            plans = self._agent_plans(plan, names) if plan.solved else direct_plans(goal_arr, names)
            if plan.solved and plan.problem is not None:
                for i, a in enumerate(names):
                    ep.states[a].set_route(plan.nodes[i][:len(plans[a].waypoints)], plan.problem,
                                           plan.problem.goal_ids[i], 0)
            self.replanner = Replanner(self.planner, self.config, self.memory, self._distance, ep)
        ep.planning_time = time.perf_counter() - t0
        ep.agents = names
        replanner = self.replanner if self.config.replanning.replan_when_stuck else None
        replan = None if replanner is None else (
            lambda agent, ob, current_plan: replanner.stuck(self.controller, agent, ob, current_plan))
        goal_order = self._goal_blockers if self.planner is not None and self.config.controller.hold == "order" \
            else None
        self.controller = WaypointController(self._policy, self._distance, plans, self.config.controller,
                                             seed=self.seed, replan=replan, fallback_policy=self._fallback,
                                             goal_order=goal_order, bound=self.bound)

    def _plan(self, starts: np.ndarray, goals: np.ndarray) -> MultiAgentPlan:
        """A joint plan without the edges the memory removed; where that leaves an agent without any
        route (the removed edges were the only way), with them."""
        assert self.planner is not None
        removed = self.memory.removed()
        budget = self.config.budget
        plan = self.planner.plan(starts, goals, budget=budget, exclude_edges=removed)
        if len(removed) and plan.status == "infeasible":
            plan = self.planner.plan(starts, goals, budget=budget)
        return plan

    def _agent_plans(self, plan: MultiAgentPlan, names: List[str]) -> Dict[str, AgentPlan]:
        """The controller's plans of a solved plan, kept by the clock or in the plan's order (``hold``)."""
        hold = self.config.controller.hold
        if hold != "order":
            return plan.agent_plans(names, hold=hold)
        plans = plan.agent_plans(names, hold="waits")
        radius = self.planner.graph.proximity_radius if self.planner is not None else None
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
        if self.planner is None:
            return
        n = len(self.planner.observations)
        for a, state in self.episode.states.items():
            seen = state.seen_index
            now = state.seen_index = self.controller.index.get(a, seen)
            self.memory.record_route(state.route, seen, now, n)

    def _goal_blockers(self, agent: str) -> List[Tuple[str, int]]:
        """The controller's ``goal_order``: :func:`~agents.search.execution.dependencies.goal_passers` of
        ``agent`` on the routes as they are now, within the planner's proximity radius."""
        assert self.planner is not None and self.controller is not None
        ep = self.episode
        state = ep.states[agent]
        if state.problem is None:
            return []
        others = {b: (ep.states[b].route, ep.states[b].problem, ep.states[b].goal_id, self.controller.index.get(b, 0))
                  for b in ep.routed() if b != agent}
        out = goal_passers(state.problem, state.goal_id, others, float(self.planner.graph.proximity_radius or 0.0))
        clearance = self.config.controller.park_clearance
        if clearance is not None:
            under_way = {b: v for b, v in others.items() if b in ep.live and b not in dict(out)}
            out += shut_out(state.problem, state.goal_id, under_way, clearance, ep.cut_cache)
        return out


__all__ = ["SearchPolicy"]
