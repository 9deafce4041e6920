"""The multi-agent goal-conditioned safe navigation environment (PettingZoo parallel API).

The parallel environment is the real one; the AEC form is derived from it with
:func:`pettingzoo.utils.conversions.parallel_to_aec`. Reach them by a registered single-agent
id (the multi-agent env inherits its map and keyword arguments)::

    import safe_mapf_envs

    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=10)
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

or through the per-map modules, e.g. ``safe_mapf_envs.multi.central_obstacle_v0.parallel_env()``.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from .base import RENDER_MODES, NavigationEnvBase
from .checks import (
    check_action,
    check_count,
    check_goal_distance,
    check_number,
    parse_reset_options,
    show,
)
from .formats import flat_space, flatten_agents
from .world import World

_RESET_OPTIONS = ("starts", "goals", "goal_distance")
#: agents up to which the nearest neighbours are found against every agent (a k-d tree beyond)
_DENSE_NEIGHBORS = 128
_NEIGHBOR_SLACK = 4  # candidates the k-d tree proposes on top of the needed ones
_ROWS_AT_ONCE = 100  # live agents from which per-agent views are made by list() (faster for many)


def _snake(name: str) -> str:
    """``CentralObstacle`` -> ``central_obstacle``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


class SafeMultiNavigationEnv(NavigationEnvBase, ParallelEnv):
    """N goal-conditioned agents navigating a shared map with a safety cost (PettingZoo parallel).

    ## Description
    ``n_agents`` circular agents move in one 2D world of static box obstacles, each towards its
    own goal, as in the multi-agent experiments of the paper "Safe Multi-Agent Navigation
    guided by Goal-Conditioned Safe Reinforcement Learning". All agents are bodies of one
    pymunk space: they collide with the walls and with each other. Every agent sees exactly
    what the single-agent environment
    (:class:`~safe_mapf_envs.single_agent.SafeNavigationEnv`) shows its agent, so a
    single-agent goal-conditioned policy runs unchanged on every agent. Being near obstacles
    is unsafe: every step reports each agent's safety cost in ``infos[agent]["cost"]``; it is
    never folded into the reward.

    World coordinates: ``x`` along the map's columns, ``y`` along its rows (row 0 at the top).

    ## Action Space
    Per agent ``Box(-1, 1, (2,), float32)``: the intended displacement ``(dx, dy)`` in world
    units over one step, applied in physics sub-steps (agents slide along walls and each
    other, never pass through them). ``step`` needs an action for every agent in
    :attr:`agents`; a missing one, an unknown agent name, NaN, inf, complex numbers or a wrong
    shape raise ``ValueError``; actions for agents that are already done are ignored; out-of-range
    actions are clipped to ``[-1, 1]``. Optional Gaussian noise (``action_noise``) is added
    after clipping.

    ## Observation Space
    Per agent the single-agent ``Dict`` (Gymnasium-Robotics goal convention):

    - ``observation``: the agent's position divided by the world size, in ``[0, 1]^2``;
    - ``achieved_goal``: the same as ``observation``;
    - ``desired_goal``: the agent's goal divided by the world size;
    - ``neighbors`` (only with ``observe_neighbors=k > 0``): shape ``(k, 2)``, the positions
      of the ``k`` nearest other agents (parked ones included) relative to this agent,
      divided by the world size, nearest first; rows beyond the ``n_agents - 1`` other agents
      are zero.

    All are ``float32``. With ``observation_format="flat"`` each agent's observation is one
    ``Box`` (for SuperSuit's wrappers and SB3's ``MlpPolicy``/``CnnPolicy``, see
    :mod:`safe_mapf_envs.formats`): ``[observation, desired_goal, neighbors]`` flattened
    (``float32``), or for panoramas the channel-first ``uint8`` image ``(4, 2S, 4S)``; the Dict
    spaces stay available as :attr:`goal_observation_spaces`. :meth:`state` is the global view:
    every agent's normalised position then every goal, flattened (``state_space``:
    ``Box(0, 1, (4 * n_agents,), float32)``).
    Subclasses provide other observation types (``obs_type``) by overriding
    :meth:`_make_observation_space` and :meth:`_observe`.

    With ``obs_type="panorama"`` (the ``SafeApartment*`` ids) ``observation``,
    ``achieved_goal`` and ``desired_goal`` are ``uint8`` RGB-D panoramas ``(4, S, S, 4)`` as
    in the single-agent env: the agent's own view, in which the other agents (parked ones
    included) stand as cylinders in their top-down colours, and the view from its goal,
    rendered once per episode without agents.

    ## Rewards
    For every agent that acted: ``0`` on the step that reaches its goal, ``-1`` otherwise, as in
    the single-agent env (the Gymnasium-Robotics sparse convention).

    ## Costs
    ``infos[agent]["cost"]``: the obstacle cost exactly as in the single-agent environment
    (the largest cost over the positions of the step's sub-steps, ``C = 2 - 2h/r`` within
    ``cost_radius`` of an obstacle for ``cost_fn="linear"``), plus ``collision_cost`` (default
    0) for every contact with another agent during the step. ``infos[agent]`` also carries
    ``obstacle_cost`` (the obstacle part alone), ``collisions`` (the number of other agents
    touched during the step), ``collided_with`` (their names), ``position`` and ``goal``
    (ground truth in world units, for evaluation only), ``distance_to_goal`` and
    ``is_success``.

    ## Starting State
    Starts and goals are sampled uniformly in the free space, starts at least
    ``min_separation`` apart from each other and goals likewise. ``reset(options=...)``
    accepts:

    - ``{"starts": [(x, y), ...], "goals": [(x, y), ...]}`` (one per agent, world units; either
      key alone works) to pin a problem. Every position must be free (as in the single-agent
      env) and no two starts (or goals) closer than ``2 * agent_radius``; otherwise
      ``ValueError`` names the agent;
    - ``{"goal_distance": (lo, hi)}`` to sample each goal at a ground-truth geodesic distance
      from its agent's start within the band (``"uniform"``: anywhere, the default here, since
      the default ``max_cycles`` of 300 steps reaches across every registered map).

    Other keys are ignored with a ``UserWarning`` that names them, as in the single-agent env
    (PettingZoo's API test passes a key of its own). ``max_start_cost`` is a constructor
    argument, not a reset option: with it set, sampled starts are restricted to positions whose
    cost is at most that value.

    Capacity is decided in the constructor, by the placement ``reset`` uses
    (:meth:`NavigationScenario.sample_separated
    <safe_mapf_envs.scenario.NavigationScenario.sample_separated>`: uniform draws, and where they
    do not separate, random positions of a deterministic packing of the map, moved at random).
    :attr:`capacity` is the size of that packing: ``reset`` places any ``n_agents`` up to it, at
    every seed, and a larger ``n_agents`` raises ``ValueError`` naming both numbers. Goals in a
    ``goal_distance`` band are drawn agent by agent and can still fail in a crowded band.

    ## Episode End
    An agent is ``terminated`` when its centre comes within ``goal_threshold`` of its goal: it
    then stays parked where it arrived, an immovable obstacle for the others (the MAPF
    convention), and leaves :attr:`agents`. After ``max_cycles`` steps every remaining agent
    is ``truncated``.

    ## Arguments
    ``safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=4, render_mode=None,
    **kwargs)`` or ``SafeMultiNavigationEnv(layout, n_agents, render_mode, **kwargs)`` with
    the single-agent keyword arguments

    - ``agent_radius`` (0.5), ``cost_radius`` (map default), ``cost_fn`` ("linear"),
      ``boundary_cost`` (False), ``goal_threshold`` (1.0), ``action_noise`` (0.0),
      ``substeps`` (4), ``max_start_cost`` (None), ``goal_distance`` (None);

    and the multi-agent ones

    - ``max_cycles`` (300, the paper's evaluation limit): steps before truncation;
    - ``min_separation`` (``2 * agent_radius + goal_threshold``): smallest distance between
      sampled starts and between sampled goals. The default keeps an agent parked anywhere
      within reach of its goal clear of every other goal; it must be at least
      ``2 * agent_radius``;
    - ``collision_cost`` (0.0): cost added per contact with another agent;
    - ``agent_collisions`` (True): ``False`` lets agents pass through each other (the
      convention of the published code of the paper: its agents never touch); walls and
      obstacles still stop them, no contacts are reported and pinned starts (and goals) may
      overlap (sampled ones keep ``min_separation``, so :attr:`capacity` bounds ``n_agents`` here
      too);
    - ``observe_neighbors`` (0): adds the ``neighbors`` key with this many nearest agents;
    - ``obs_type`` ("vector" or "panorama"): the observation type (see :attr:`obs_types`);
    - ``observation_format`` ("dict" or "flat"): see Observation Space;
    - ``action_scale`` (1.0): world units per unit of action; ``sensor_kwargs`` (None): camera
      settings for panoramas (see :class:`~safe_mapf_envs.sensors.PanoramaSensor`).

    ``render_mode="rgb_array"`` returns a top-down image with the cost heat map, every agent
    in its own colour with its goal and trail, parked agents ringed, collision markers and
    the planned waypoints of :meth:`set_waypoints`; ``"human"`` shows it in a matplotlib
    window and needs a display (without one it warns and shows nothing).

    Helpers shared with the single-agent env (see :class:`~safe_mapf_envs.base.NavigationEnvBase`):
    :meth:`sample_states`, :meth:`geodesic_distance`, :meth:`observations_at`, :meth:`normalize`.

    ## Version History
    - v0: initial release.
    """

    metadata = {
        "render_modes": list(RENDER_MODES),
        "name": "safe_multi_navigation_v0",
        "is_parallelizable": True,
        "render_fps": 10,
    }

    def __init__(
        self,
        layout="CentralObstacle",
        n_agents: int = 4,
        render_mode: Optional[str] = None,
        *,
        obs_type: str = "vector",
        max_cycles: int = 300,
        agent_radius: float = 0.5,
        cost_radius: Optional[float] = None,
        cost_fn: str = "linear",
        boundary_cost: bool = False,
        goal_threshold: float = 1.0,
        action_noise: float = 0.0,
        substeps: int = 4,
        max_start_cost: Optional[float] = None,
        goal_distance: Union[None, str, Tuple[float, float]] = None,
        min_separation: Optional[float] = None,
        collision_cost: float = 0.0,
        agent_collisions: bool = True,
        observe_neighbors: int = 0,
        action_scale: float = 1.0,
        sensor_kwargs: Optional[Dict[str, Any]] = None,
        observation_format: str = "dict",
    ) -> None:
        n_agents = check_count(n_agents, "n_agents", 1)
        self.max_cycles = check_count(max_cycles, "max_cycles", 1)
        self.observe_neighbors = check_count(observe_neighbors, "observe_neighbors", 0)
        self.collision_cost = check_number(collision_cost, "collision_cost")
        if not isinstance(agent_collisions, (bool, np.bool_)):
            raise ValueError(f"agent_collisions must be True or False, got {show(agent_collisions)}")
        self.agent_collisions = bool(agent_collisions)
        self._setup(
            layout, render_mode, obs_type=obs_type, agent_radius=agent_radius, cost_radius=cost_radius,
            cost_fn=cost_fn, boundary_cost=boundary_cost, goal_threshold=goal_threshold, action_noise=action_noise,
            substeps=substeps, max_start_cost=max_start_cost, goal_distance=goal_distance, action_scale=action_scale,
            sensor_kwargs=sensor_kwargs, observation_format=observation_format,
        )
        radius = self.scenario.agent_radius
        if min_separation is None:
            min_separation = 2.0 * radius + self.goal_threshold
        min_separation = check_number(min_separation, "min_separation")
        if min_separation < 2.0 * radius:
            raise ValueError(
                f"min_separation must be at least 2 * agent_radius = {2.0 * radius:g} (agents would overlap), "
                f"got {show(min_separation)}"
            )
        self.min_separation = min_separation
        #: The most agents this env takes: every ``reset`` places that many (see Starting State).
        self.capacity = self.scenario.check_agent_count(n_agents, min_separation, self.max_start_cost)
        self.metadata = {**type(self).metadata, "name": f"{_snake(self.scenario.layout.name)}_v0"}
        self._goal_images = np.zeros((n_agents, 0), dtype=np.uint8)

        self.possible_agents: List[str] = [f"agent_{i}" for i in range(n_agents)]
        self.agent_name_mapping: Dict[str, int] = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: List[str] = []
        self.action_spaces = {a: spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32) for a in self.possible_agents}
        #: Each agent's goal-conditioned Dict space (its observation space unless ``observation_format="flat"``).
        self.goal_observation_spaces = {a: self._make_observation_space() for a in self.possible_agents}
        self.observation_spaces: Dict[str, spaces.Space] = dict(self.goal_observation_spaces)
        if self.observation_format == "flat":
            self.observation_spaces = {a: flat_space(sp) for a, sp in self.goal_observation_spaces.items()}
        self.state_space = spaces.Box(0.0, 1.0, shape=(4 * n_agents,), dtype=np.float32)

        self.np_random, self.np_random_seed = seeding.np_random()
        self._world: Optional[World] = None
        self._pos = np.zeros((n_agents, 2))
        self._goals = np.zeros((n_agents, 2))
        self._goals_norm = np.zeros((n_agents, 2), dtype=np.float32)
        self._live = np.zeros(n_agents, dtype=bool)
        self._live_idx = np.zeros(0, dtype=np.intp)
        self._t = 0
        self._trail: List[np.ndarray] = []
        self._collision_points: List[np.ndarray] = []
        self._waypoints: List[Optional[np.ndarray]] = [None] * n_agents
        self._open_window()

    # ----------------------------------------------------------------- spaces
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (the same object on every call)."""
        return self.action_spaces[agent]

    def _make_observation_space(self) -> spaces.Dict:
        """One agent's observation space; override together with :meth:`_observe`."""
        pos: spaces.Box
        if self.sensor is not None:
            pos = spaces.Box(0, 255, shape=self.sensor.shape, dtype=np.uint8)
        else:
            pos = spaces.Box(0.0, 1.0, shape=(2,), dtype=np.float32)
        keys: Dict[str, spaces.Space] = {"observation": pos, "achieved_goal": pos, "desired_goal": pos}
        if self.observe_neighbors:
            keys["neighbors"] = spaces.Box(-1.0, 1.0, shape=(self.observe_neighbors, 2), dtype=np.float32)
        return spaces.Dict(keys)

    # ----------------------------------------------------------------- properties
    @property
    def n_agents(self) -> int:
        """Number of agents, live or not (``len(possible_agents)``)."""
        return len(self.possible_agents)

    @property
    def positions(self) -> np.ndarray:
        """Ground-truth positions of all agents (world units), shape ``(n_agents, 2)``."""
        return self._pos.copy()

    @property
    def goals(self) -> np.ndarray:
        """Ground-truth goals of all agents (world units), shape ``(n_agents, 2)``."""
        return self._goals.copy()

    @property
    def parked(self) -> np.ndarray:
        """``True`` for agents that reached their goal and are parked there."""
        return np.zeros(self.n_agents, bool) if self._world is None else self._world.parked.copy()

    # ----------------------------------------------------------------- helpers
    def set_waypoints(
        self, waypoints: Union[None, Mapping[str, Optional[np.ndarray]], Sequence[Optional[np.ndarray]]]
    ) -> None:
        """Planned waypoints to draw in rendered frames.

        Args:
            waypoints: a dict from agent name to that agent's waypoints (world units,
                ``(K, 2)``, or ``None`` to clear them; agents not named keep theirs), a
                sequence of ``n_agents`` such entries in agent order, or ``None`` to clear all.
        """
        if waypoints is None:
            self._waypoints = [None] * self.n_agents
            return
        if isinstance(waypoints, Mapping):
            unknown = [a for a in waypoints if a not in self.agent_name_mapping]
            if unknown:
                raise ValueError(f"set_waypoints: unknown agent names {unknown}; agents are {self._agent_range()}")
            items = [(self.agent_name_mapping[a], w) for a, w in waypoints.items()]
        else:
            if len(waypoints) != self.n_agents:
                raise ValueError(
                    f"set_waypoints: a sequence needs one entry per agent ({self.n_agents}), got {len(waypoints)}; "
                    "pass a dict agent -> waypoints for some agents only"
                )
            items = list(enumerate(waypoints))
        for i, w in items:
            if w is None:
                self._waypoints[i] = None
                continue
            arr = np.asarray(w, dtype=np.float64)
            if arr.size == 0:
                self._waypoints[i] = None
                continue
            if arr.ndim != 2 or arr.shape[1] != 2:
                raise ValueError(
                    f"set_waypoints: waypoints of {self.possible_agents[i]} must have shape (K, 2), got {arr.shape}"
                )
            self._waypoints[i] = arr

    def _agent_range(self) -> str:
        return f"agent_0 .. agent_{self.n_agents - 1}"

    # ----------------------------------------------------------------- problem set-up
    def _check_positions(self, points, what: str) -> np.ndarray:
        """Validate user-given starts or goals (see :meth:`NavigationScenario.check_agent_positions
        <safe_mapf_envs.scenario.NavigationScenario.check_agent_positions>`)."""
        return self.scenario.check_agent_positions(points, self.n_agents, what, overlap_ok=not self.agent_collisions)

    def _sample_separated(self, rng: np.random.Generator, what: str, max_cost: Optional[float] = None) -> np.ndarray:
        """``n_agents`` free positions at least ``min_separation`` apart.

        Every round redraws the later agent of each pair that is too close, so the result
        depends on the generator alone (see :meth:`NavigationScenario.sample_separated
        <safe_mapf_envs.scenario.NavigationScenario.sample_separated>`).
        """
        return self.scenario.sample_separated(
            self.n_agents, self.min_separation, rng, max_cost=max_cost, what=what, separation_name="min_separation"
        )

    def _sample_goals_in_band(self, starts: np.ndarray, band, rng: np.random.Generator) -> np.ndarray:
        """One goal per agent at a geodesic distance from its own start within ``band``, at least
        ``min_separation`` apart (see :meth:`NavigationScenario.sample_goals_in_band
        <safe_mapf_envs.scenario.NavigationScenario.sample_goals_in_band>`)."""
        return self.scenario.sample_goals_in_band(starts, band, self.min_separation, rng)

    # ----------------------------------------------------------------- observations
    def _observe(self, idx: np.ndarray) -> Dict[str, Any]:
        """Observations of the agents with indices ``idx``, keyed by agent name.

        The one place observations are built: subclasses with another ``obs_type`` override
        it (and :meth:`_make_observation_space`). Ground truth is in ``self._pos`` and
        ``self._goals`` (world units, all agents).
        """
        n = len(idx)
        pos = self._pos[idx]
        if self.sensor is not None:  # each agent's view, with the other agents in it
            img = self.sensor.render(pos, agents=self._pos, agent_radius=self.scenario.agent_radius, self_index=idx)
            buf = np.stack([img, img, self._goal_images[idx]], axis=1)
        else:
            buf = np.empty((n, 3, 2), dtype=np.float32)
            buf[:, 0] = pos * self._inv_size
            buf[:, 1] = buf[:, 0]
            buf[:, 2] = self._goals_norm[idx]
        names = [self.possible_agents[i] for i in idx.tolist()]
        # each agent's entries are views of its row of buf (list() makes many at C speed)
        if n > _ROWS_AT_ONCE:
            own, achieved, goal = list(buf[:, 0]), list(buf[:, 1]), list(buf[:, 2])
        else:
            own, achieved, goal = [b[0] for b in buf], [b[1] for b in buf], [b[2] for b in buf]
        if not self.observe_neighbors:
            return {
                name: {"observation": o, "achieved_goal": a, "desired_goal": g}
                for name, o, a, g in zip(names, own, achieved, goal)
            }
        nb = self._neighbors(idx, pos)
        return {
            name: {"observation": o, "achieved_goal": a, "desired_goal": g, "neighbors": k}
            for name, o, a, g, k in zip(names, own, achieved, goal, nb)
        }

    def _formatted(self, idx: np.ndarray) -> Dict[str, Any]:
        """:meth:`_observe`, flattened with ``observation_format="flat"``."""
        obs = self._observe(idx)
        return flatten_agents(obs) if self.observation_format == "flat" else obs

    def _neighbors(self, idx: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Normalised offsets to the ``observe_neighbors`` nearest other agents, ``(len(idx), k, 2)``.

        Nearest first, ties in agent order. With many agents a k-d tree proposes a few more
        candidates than needed per agent and the exact distances order them; an agent whose
        candidates may miss a tie at the edge (agents passing through each other can share a
        place) is measured against every agent, as small crowds always are.
        """
        k = self.observe_neighbors
        n_all = self.n_agents
        m = min(k, n_all - 1)
        out = np.zeros((len(idx), k, 2), dtype=np.float32)
        if m == 0 or len(idx) == 0:
            return out
        q = m + 1 + _NEIGHBOR_SLACK  # oneself, the m nearest and a few more
        if n_all <= max(_DENSE_NEIGHBORS, q):
            out[:, :m] = self._nearest_dense(idx, pos, m)
            return out
        from scipy.spatial import cKDTree  # here: importing the package stays light

        kd_dist, cand = cKDTree(self._pos).query(pos, k=q)
        rel = self._pos[cand] - pos[:, None]  # (n, q, 2), world units, as the dense computation has them
        d2 = (rel * rel).sum(-1)
        d2[cand == idx[:, None]] = np.inf  # not oneself
        order = np.lexsort((cand, d2), axis=-1)[:, :m]  # by distance, then agent index (a stable argsort)
        nearest_d2 = np.take_along_axis(d2, order[:, -1:], axis=1)[:, 0]
        # every agent the tree left out is at least its q-th distance away (up to rounding)
        safe = np.sqrt(nearest_d2) < kd_dist[:, -1] * (1.0 - 1e-9)
        out[:, :m] = np.take_along_axis(rel, order[..., None], axis=1) * self._inv_size
        if not safe.all():
            bad = np.flatnonzero(~safe)
            out[bad, :m] = self._nearest_dense(idx[bad], pos[bad], m)
        return out

    def _nearest_dense(self, idx: np.ndarray, pos: np.ndarray, m: int) -> np.ndarray:
        """Normalised offsets to the ``m`` nearest other agents against every agent, ``(len(idx), m, 2)``."""
        rel = self._pos[None] - pos[:, None]  # (n, N, 2), world units
        d2 = (rel * rel).sum(-1)
        d2[np.arange(len(idx)), idx] = np.inf  # not oneself
        order = np.argsort(d2, axis=1, kind="stable")[:, :m]
        return np.take_along_axis(rel, order[..., None], axis=1) * self._inv_size

    def _infos(self, idx: np.ndarray, obstacle_cost: np.ndarray, dist: np.ndarray, counts: np.ndarray,
               partners: Dict[int, List[int]]) -> Dict[str, Dict[str, Any]]:
        """Per-agent infos; ``dist`` is each agent's distance to its goal, ``counts`` its contacts."""
        pos, goals = self._pos.copy(), self._goals.copy()  # copies: the caller may keep or edit them
        cnt = counts[idx]
        cost = obstacle_cost + self.collision_cost * cnt if self.collision_cost else obstacle_cost
        names, thr = self.possible_agents, self.goal_threshold
        live = idx.tolist()
        if len(live) > _ROWS_AT_ONCE:  # rows of the copies, as views made at C speed
            at, to = list(pos[idx]), list(goals[idx])
        else:
            at, to = [pos[i] for i in live], [goals[i] for i in live]
        rows = zip(live, at, to, cost.tolist(), obstacle_cost.tolist(), dist.tolist(), cnt.tolist())
        return {
            names[i]: {
                "cost": c,
                "obstacle_cost": oc,
                "position": p,
                "goal": g,
                "distance_to_goal": d,
                "is_success": d <= thr,
                "collisions": k,
                "collided_with": [names[j] for j in partners[i]] if k else [],
            }
            for i, p, g, c, oc, d, k in rows
        }

    # ----------------------------------------------------------------- PettingZoo API
    def reset(self, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None):
        """Start an episode; see Starting State in the class docstring for ``options``."""
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(seed)
        options = parse_reset_options(options, _RESET_OPTIONS, type(self).__name__)
        sc, rng = self.scenario, self.np_random
        if options.get("starts") is not None:
            starts = self._check_positions(options["starts"], "start")
        else:
            starts = self._sample_separated(rng, "start", max_cost=self.max_start_cost)
        band = check_goal_distance(options["goal_distance"]) if "goal_distance" in options else self.goal_distance
        if options.get("goals") is not None:
            goals = self._check_positions(options["goals"], "goal")
        elif isinstance(band, tuple):  # a (lo, hi) band; None and "uniform" mean anywhere
            goals = self._sample_goals_in_band(starts, band, rng)
        else:
            goals = self._sample_separated(rng, "goal")
        n = self.n_agents
        # a new pymunk space every episode: reusing one across resets is not deterministic
        self._world = World(sc.size, sc.boxes, starts, sc.agent_radius, self.substeps,
                            agent_collisions=self.agent_collisions)
        self._pos = starts.copy()
        self._goals = goals
        self._goals_norm = self.normalize(goals)
        if self.sensor is not None:
            self._goal_images = self.sensor.render(goals)
        self._live = np.ones(n, dtype=bool)
        self._live_idx = np.arange(n)
        self._t = 0
        self.agents = self.possible_agents[:]
        self._trail = [starts.copy()]
        self._collision_points = []
        idx = self._live_idx
        dist = np.sqrt(((starts - goals) ** 2).sum(-1))
        infos = self._infos(idx, sc.field.cost(starts), dist, np.zeros(n, np.int64), {})
        return self._formatted(idx), infos

    def _parse_actions(self, actions) -> np.ndarray:
        """Actions of the live agents as an ``(n_live, 2)`` float64 array, validated."""
        if not isinstance(actions, Mapping):
            raise ValueError(f"actions must be a dict from agent name to action, got {type(actions).__name__}")
        agents = self.agents
        missing = [a for a in agents if a not in actions]
        if missing:
            raise ValueError(f"missing actions for live agents {missing}: every agent in env.agents needs one")
        if len(actions) != len(agents):
            unknown = [a for a in actions if a not in self.agent_name_mapping]
            if unknown:
                raise ValueError(f"actions for unknown agents {unknown}; agents are {self._agent_range()}")
        acts = [actions[a] for a in agents]
        try:
            raw = np.array(acts)
            ok = raw.dtype.kind in "fiub"  # not complex, strings or objects
            if ok:
                arr = raw.astype(np.float64)
                ok = arr.shape == (len(agents), 2) and bool(np.isfinite(arr).all())
        except (TypeError, ValueError):
            ok = False
        if not ok:  # find the culprit and say what is wrong with it
            for name, act in zip(agents, acts):
                try:
                    check_action(act)
                except ValueError as exc:
                    raise ValueError(f"{name}: {exc}") from None
            raise ValueError(f"actions must be (2,) arrays of finite real numbers, got {show(actions)}")
        return arr

    def step(self, actions: Dict[str, Any]):
        """Move every live agent by its action; returns PettingZoo's five per-agent dicts."""
        if self._world is None:
            raise RuntimeError("call reset() before step()")
        if not self.agents:
            if not isinstance(actions, Mapping):
                raise ValueError(f"actions must be a dict from agent name to action, got {type(actions).__name__}")
            return {}, {}, {}, {}, {}
        a = np.clip(self._parse_actions(actions), -1.0, 1.0)
        if self.action_noise > 0:
            a += self.np_random.normal(0.0, self.action_noise, size=a.shape)
        idx = self._live_idx
        n = self.n_agents
        disp = np.zeros((n, 2))
        disp[idx] = a * self.action_scale
        trace, contacts = self._world.step(disp)
        self._pos = trace[-1]
        obstacle_cost = self.scenario.field.cost(trace[:, idx]).max(axis=0)

        counts = np.zeros(n, dtype=np.int64)
        partners: Dict[int, List[int]] = {}
        if contacts:
            pairs = np.array(sorted(contacts), dtype=np.intp)
            np.add.at(counts, pairs.ravel(), 1)
            for i, j in pairs.tolist():
                partners.setdefault(i, []).append(j)
                partners.setdefault(j, []).append(i)
            for lst in partners.values():
                lst.sort()

        self._t += 1
        truncated = self._t >= self.max_cycles
        names = self.agents
        dist = np.sqrt(((self._pos[idx] - self._goals[idx]) ** 2).sum(-1))
        infos = self._infos(idx, obstacle_cost, dist, counts, partners)
        reached = dist <= self.goal_threshold
        for i in idx[reached].tolist():
            self._world.park(i)
        observations = self._formatted(idx)
        rewards = dict(zip(names, np.where(reached, 0.0, -1.0).tolist()))
        terminations = dict(zip(names, reached.tolist()))
        truncations = dict.fromkeys(names, truncated)
        if truncated or reached.any():
            self._live[idx[reached]] = False
            if truncated:
                self._live[:] = False
            self._live_idx = np.flatnonzero(self._live)
            self.agents = [self.possible_agents[i] for i in self._live_idx.tolist()]

        if self.render_mode is not None:
            self._trail.append(self._pos.copy())
            for i, j in contacts:
                self._collision_points.append(0.5 * (self._pos[i] + self._pos[j]))
            if self.render_mode == "human":
                self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """Every agent's normalised position, then every normalised goal, flattened (float32)."""
        return np.concatenate([self.normalize(self._pos).ravel(), self._goals_norm.ravel()])

    # ----------------------------------------------------------------- rendering
    def render(self) -> Optional[np.ndarray]:
        """The top-down frame (``rgb_array``), or ``None`` after showing it (``human``)."""
        if self.render_mode is not None and self._world is None:
            raise RuntimeError("call reset() before render()")
        trails = np.stack(self._trail, axis=1) if self._trail else np.zeros((self.n_agents, 0, 2))  # (N, T, 2)
        return self._draw(
            self._pos, self._goals, list(trails), self._waypoints,
            collisions=self._collision_points, parked=None if self._world is None else self._world.parked,
        )


__all__ = ["SafeMultiNavigationEnv"]
