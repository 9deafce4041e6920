"""The single-agent goal-conditioned safe navigation environment (Gymnasium)."""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .base import RENDER_MODES, NavigationEnvBase
from .checks import check_action, check_count, check_goal_distance, parse_reset_options, show
from .formats import flat_space, flatten_observation
from .world import World

_RESET_OPTIONS = ("start", "goal", "goal_distance")
#: action dtypes that :meth:`SafeNavigationEnv.step` reads without :func:`check_action` (same result)
_FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


class _dict_format_only:
    """A method that exists only on envs with ``observation_format="dict"``: on the flat format
    reading it raises ``AttributeError``, so ``hasattr(env, name)`` is ``False`` there."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn
        self.__doc__ = fn.__doc__
        self.name = fn.__name__

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, objtype: Optional[type] = None) -> Callable[..., Any]:
        if obj is None:
            return self.fn
        if getattr(obj, "observation_format", "dict") != "dict":
            raise AttributeError(
                f"{self.name} is defined with observation_format='dict' only (the goal-conditioned format); "
                "this env has observation_format='flat': use compute_terminated, which takes the same goals"
            )
        return self.fn.__get__(obj, objtype)


class SafeNavigationEnv(NavigationEnvBase, gym.Env):
    """Goal-conditioned navigation with a safety cost, on a pymunk collision world.

    ## Description
    A circular agent moves in a 2D world of static box obstacles and must reach a goal. Being
    near obstacles is unsafe: every step reports a safety cost (``info["cost"]``) that grows as
    the agent approaches an obstacle, following the paper "Safe Multi-Agent Navigation guided
    by Goal-Conditioned Safe Reinforcement Learning". The cost is never folded into the reward:
    constrained RL methods read it from ``info`` (or use
    :class:`~safe_mapf_envs.wrappers.SafetyGymnasiumStyle`).

    World coordinates: ``x`` runs along the map's columns, ``y`` along its rows (row 0 at the
    top, as in the rendered image); a map of ``H x W`` cells with resize factor ``f`` spans
    ``(W*f) x (H*f)`` units.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: the intended displacement ``(dx, dy)`` over one step, in
    units of ``action_scale`` world units (1 on the 2D maps, 0.25 m on the apartments). It is
    applied in physics sub-steps, so the agent slides along walls and never passes through
    them. Out-of-range actions are clipped to ``[-1, 1]``; NaN, inf, complex numbers and wrong
    shapes raise ``ValueError``. Optional Gaussian noise (``action_noise``) is added after clipping.

    ## Observation Space
    A ``Dict`` in the goal-conditioned convention of Gymnasium-Robotics (usable with SB3's
    ``MultiInputPolicy`` and ``HerReplayBuffer``):

    - ``observation``: the agent's position divided by the world size, in ``[0, 1]^2``;
    - ``achieved_goal``: the same as ``observation``;
    - ``desired_goal``: the goal's position divided by the world size.

    All are ``float32``. Ground-truth positions in world units are in ``info["position"]`` and
    ``info["goal"]`` (for evaluation, never meant as policy input).

    With ``observation_format="flat"`` the observation is one ``Box`` instead (for SB3's
    ``MlpPolicy``/``CnnPolicy`` and tools that take no ``Dict``, see
    :mod:`safe_mapf_envs.formats`): ``[observation, desired_goal]`` (``float32``, 4 values) for
    vectors, and for panoramas the channel-first ``uint8`` image ``(4, 2S, 4S)`` with the
    agent's four views on top and the goal's below. The Dict space stays available as
    :attr:`goal_observation_space`; :meth:`compute_terminated`, :meth:`compute_truncated` and
    :meth:`compute_cost` take its goals. :meth:`compute_reward` exists on the Dict format only, so
    that tools which take an env with ``compute_reward`` for a goal env (SB3's ``check_env`` and
    ``HerReplayBuffer``) take the flat env for a plain one.

    With ``obs_type="panorama"`` (the ``SafeApartment*`` ids) the three keys are images
    instead: ``Box(0, 255, (4, S, S, 4), uint8)``, the views north, east, south and west
    (``-y``, ``+x``, ``+y``, ``-x``), each ``S x S`` (32) pixels with channels R, G, B and depth
    (``255 * min(d / sensor range, 1)``), rendered by
    :class:`~safe_mapf_envs.sensors.PanoramaSensor` from the agent's position
    (``observation``, ``achieved_goal``) and from the goal (``desired_goal``, rendered once per
    episode), as in the paper's visual tasks. On the 2D maps the walls are extruded to a
    height (see :func:`~safe_mapf_envs.sensors.grid_scene`). The images never depend on
    ``render_mode``. ``sensor_kwargs`` sets the camera (``image_size``, ``fov``,
    ``camera_height``, ``max_range``).

    ## Rewards
    ``-1`` on every step that ends away from the goal and ``0`` on the step that reaches it
    (the Gymnasium-Robotics sparse convention, ``-(not terminated)``). :meth:`compute_reward`
    computes the same from ``(achieved_goal, desired_goal)``, on single goals or batches, so
    SB3's ``HerReplayBuffer`` sees a relabelled transition that reaches its new goal as one
    (it does not relabel ``dones``; a goal-reaching transition is told apart by its reward).
    An episode of ``T`` steps that reaches the goal has the return ``-(T - 1)``.

    The distance critics of :class:`~agents.SafeGoalTD3` do not read this reward: they count
    the steps to the goal themselves (one per step, the goal-reaching step included, from the
    termination that their replay buffer recomputes for every relabelled goal), as Search on the
    Replay Buffer does.

    ## Costs
    ``info["cost"]`` is the largest cost over the positions of the step's sub-steps:
    ``C = 2 - 2h/r`` for ``h <= r`` and 0 beyond (``cost_fn="linear"``, the paper's eq. 5),
    with ``h`` the exact distance from the agent's centre to the nearest obstacle boundary
    and ``r`` = ``cost_radius``. ``"cosine"`` and ``"constant"`` profiles are available. The
    outer boundary confines the agent but costs nothing unless ``boundary_cost=True``.
    :meth:`compute_cost` gives the cost at the position of an achieved goal (vector
    observations only), for cost relabelling: it does not depend on the goal, and it is the
    cost of the step's last sub-step, so at most the step's ``info["cost"]``.

    ## Starting State
    The start is sampled uniformly in the free space (positions whose distance to every
    obstacle is at least the agent radius). The registered ids sample the goal **within reach
    of their time limit**: ``goal_distance=(0, 20 * action_scale)``, a ground-truth geodesic
    distance from the start of at most 20 units (5 m on the apartments), the distance an
    agent moving at full speed along the shortest path covers in the 20 steps of an episode.
    Pass ``goal_distance="uniform"`` for goals anywhere in the free space (the class's own
    default), or a ``(lo, hi)`` band; with a longer ``max_episode_steps``, widen the band to
    match (it is not read from the time limit). ``reset(options=...)`` accepts:

    - ``{"start": (x, y), "goal": (x, y)}`` to pin a problem (world units; either key alone works);
    - ``{"goal_distance": (lo, hi)}`` (or ``"uniform"``) for this episode's goal, as the
      constructor argument.

    Other keys are ignored with a ``UserWarning`` that names them, in both the single- and
    the multi-agent env (generic tools such as PettingZoo's API test pass keys of their own).
    ``max_start_cost`` is a constructor argument, not a reset option: with it set, sampled
    starts are restricted to positions whose cost is at most that value.

    ## Episode End
    ``terminated`` when the agent's centre is within ``goal_threshold`` units of the goal;
    ``truncated`` after ``max_episode_steps`` (20 for the registered ids, as in the paper; pass
    ``max_episode_steps=...`` to ``gymnasium.make`` for longer evaluation episodes).

    Termination is always decided from ground truth. :meth:`compute_terminated` sees only the
    goals it is given: with vector goals it applies the same ``goal_threshold`` rule; with
    image goals it cannot recover positions, so it returns ``True`` exactly where the two
    panoramas are identical pixel for pixel (a relabelled goal that is the achieved panorama
    itself). Near the goal, ``step`` may terminate (with reward 0) while the images still
    differ, where :meth:`compute_reward` gives -1; use ``info["is_success"]`` to evaluate.

    ## Arguments
    ``gymnasium.make("SafeCentralObstacle-v0", render_mode=None, **kwargs)`` with kwargs:

    - ``layout``: map name or layout object (set by the registered id);
    - ``agent_radius`` (0.5), ``cost_radius`` (map default; 10 on CentralObstacle),
      ``cost_fn`` ("linear"), ``boundary_cost`` (False);
    - ``goal_threshold`` (1.0), ``action_noise`` (0.0, std of Gaussian noise on the action),
      ``substeps`` (4);
    - ``max_start_cost`` (None), ``goal_distance`` (``None`` or ``"uniform"``: goals anywhere;
      a ``(lo, hi)`` geodesic band; the registered ids set ``(0, 20 * action_scale)``, see
      Starting State);
    - ``observation_format`` ("dict" or "flat", see Observation Space);
    - ``obs_type`` ("vector" or "panorama"), ``action_scale`` (1.0; world units per unit of
      action), ``sensor_kwargs`` (None: :class:`~safe_mapf_envs.sensors.PanoramaSensor`
      arguments for panoramas);
    - ``parked_agents`` (0): this many other agents stand still in the episode, immovable
      obstacles as agents parked at their goals are in the multi-agent env, each drawn near the
      straight line from the start to the goal (a third of the way to two thirds, up to two
      agent radii to either side), where they leave the start and the goal free and do not
      overlap (a place that does not fit is skipped). Panoramas show them as the
      multi-agent env shows other agents; the goal's panorama does not, as there, and neither
      does ``achieved_goal`` (the place seen as a goal, what hindsight relabelling takes), so
      relabelled goals look like real ones. For training agents that meet parked agents on their
      way; ``info["parked"]`` holds their positions;
    - ``parked_fraction`` (1.0): the share of episodes that have the parked agents (each
      episode draws it; the others have none), so an agent can learn both kinds.

    The apartment ids (``SafeApartment0-v0`` .. ``SafeApartment3-v0``) are in metres with
    ``agent_radius=0.2``, ``action_scale=0.25``, ``goal_threshold=0.5``, cost radius 1 and
    panorama observations; ``SafeCentralObstacleVisual-v0`` is the 2D benchmark seen in
    panoramas.

    ``render_mode="rgb_array"`` returns a top-down image with the cost heat map, obstacles,
    agent, goal, trail and planned waypoints (see :meth:`set_waypoints`); ``"human"`` shows it
    in a matplotlib window and needs a display (without one it warns and shows nothing).

    Helpers for evaluation and planning (shared with the multi-agent env, see
    :class:`~safe_mapf_envs.base.NavigationEnvBase`): :meth:`sample_states`,
    :meth:`geodesic_distance`, :meth:`observations_at`, :meth:`normalize`.

    SB3's ``check_env`` calls ``compute_reward`` on the object it is given, which Gymnasium's
    wrappers do not forward: check ``gymnasium.make(id).unwrapped``. With
    ``observation_format="flat"`` the env has no ``compute_reward`` and passes the checker as a
    plain env, wrapped or not.

    ## Version History
    - v0: initial release.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 10}

    def __init__(
        self,
        layout="CentralObstacle",
        render_mode: Optional[str] = None,
        *,
        agent_radius: float = 0.5,
        cost_radius: Optional[float] = None,
        cost_fn: str = "linear",
        boundary_cost: bool = False,
        goal_threshold: float = 1.0,
        action_noise: float = 0.0,
        substeps: int = 4,
        max_start_cost: Optional[float] = None,
        goal_distance: Union[None, str, Tuple[float, float]] = None,
        obs_type: str = "vector",
        action_scale: float = 1.0,
        sensor_kwargs: Optional[Dict[str, Any]] = None,
        observation_format: str = "dict",
        parked_agents: int = 0,
        parked_fraction: float = 1.0,
    ) -> None:
        self.parked_agents = check_count(parked_agents, "parked_agents", 0)
        if not 0.0 <= parked_fraction <= 1.0:  # also refuses NaN
            raise ValueError(f"parked_fraction must be in [0, 1], got {show(parked_fraction)}")
        self.parked_fraction = float(parked_fraction)
        self._setup(
            layout, render_mode, obs_type=obs_type, agent_radius=agent_radius, cost_radius=cost_radius,
            cost_fn=cost_fn, boundary_cost=boundary_cost, goal_threshold=goal_threshold, action_noise=action_noise,
            substeps=substeps, max_start_cost=max_start_cost, goal_distance=goal_distance, action_scale=action_scale,
            sensor_kwargs=sensor_kwargs, observation_format=observation_format,
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        pos_space: spaces.Box
        if self.sensor is not None:
            pos_space = spaces.Box(0, 255, shape=self.sensor.shape, dtype=np.uint8)
        else:
            pos_space = spaces.Box(0.0, 1.0, shape=(2,), dtype=np.float32)
        self._goal_ndim = len(pos_space.shape)
        self._goal_image = np.zeros(0, dtype=np.uint8)
        #: The goal-conditioned Dict space (the observation space unless ``observation_format="flat"``).
        self.goal_observation_space = spaces.Dict(
            {"observation": pos_space, "achieved_goal": pos_space, "desired_goal": pos_space}
        )
        self.observation_space: spaces.Space = self.goal_observation_space
        if self.observation_format == "flat":
            self.observation_space = flat_space(self.goal_observation_space)
        self._world: Optional[World] = None
        self._pos = np.zeros(2)
        self._goal = np.zeros(2)
        self._goal_norm = np.zeros(2, dtype=np.float32)
        self._trail: List[np.ndarray] = []
        self._waypoints: Optional[np.ndarray] = None
        #: positions of the parked agents of the episode (``parked_agents``), ``(M, 2)``
        self._parked = np.zeros((0, 2))
        self._open_window()

    # ----------------------------------------------------------------- properties
    @property
    def position(self) -> np.ndarray:
        """Ground-truth agent position (world units)."""
        return self._pos.copy()

    @property
    def goal(self) -> np.ndarray:
        """Ground-truth goal position (world units)."""
        return self._goal.copy()

    # ----------------------------------------------------------------- helpers
    def set_waypoints(self, waypoints: Optional[np.ndarray]) -> None:
        """Planned waypoints (world units, ``(K, 2)``) to draw in rendered frames; ``None`` clears them."""
        self._waypoints = None if waypoints is None else np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)

    def _obs(self) -> Union[Dict[str, np.ndarray], np.ndarray]:
        if self.sensor is not None:
            img = self.sensor.render(self._pos, agents=self._parked, agent_radius=self.scenario.agent_radius)
            # the place as a goal shows it: goals' panoramas never show other agents
            achieved = self.sensor.render(self._pos) if len(self._parked) else img.copy()
            obs = {"observation": img, "achieved_goal": achieved, "desired_goal": self._goal_image.copy()}
        else:
            p = self.normalize(self._pos)
            obs = {"observation": p, "achieved_goal": p.copy(), "desired_goal": self._goal_norm.copy()}
        return flatten_observation(obs) if self.observation_format == "flat" else obs

    def _info(self, cost: float) -> Dict[str, Any]:
        d = self._pos - self._goal
        dist = math.sqrt(d.dot(d))  # np.linalg.norm of a vector, without its dispatch
        return {
            "cost": cost,
            "position": self._pos.copy(),
            "goal": self._goal.copy(),
            "distance_to_goal": dist,
            "is_success": dist <= self.goal_threshold,
            **({"parked": self._parked.copy()} if self.parked_agents else {}),
        }

    def draw_problem(self, rng: np.random.Generator, options: Dict[str, Any]) -> Tuple[np.ndarray, np.ndarray]:
        """The ``(start, goal)`` of an episode (world units) from ``rng`` and parsed reset ``options``.

        What :meth:`reset` draws, in the same order from the same generator (the native vector
        env draws each sub-env's problems with it too).
        """
        sc = self.scenario
        if options.get("start") is not None:
            start = sc.check_position(options["start"], "start")
        else:
            start = sc.sample_states(1, rng, max_cost=self.max_start_cost)[0]
        band = check_goal_distance(options["goal_distance"]) if "goal_distance" in options else self.goal_distance
        if options.get("goal") is not None:
            goal = sc.check_position(options["goal"], "goal")
        elif isinstance(band, tuple):  # a (lo, hi) band; None and "uniform" mean anywhere
            goal = sc.sample_goal_in_band(start, band, rng)
        else:
            goal = sc.sample_states(1, rng)[0]
        return start, goal

    def draw_parked(self, rng: np.random.Generator, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Up to ``parked_agents`` positions of parked agents on the way from ``start`` to ``goal``, ``(M, 2)``.

        Each is drawn a third to two thirds of the way along the straight line, up to two agent
        radii to either side; a draw that is not free, or where an agent would overlap the one at
        the start, at the goal or another parked agent, is skipped.
        """
        sc = self.scenario
        r = sc.agent_radius
        d = goal - start
        length = float(np.hypot(d[0], d[1]))
        normal = np.array([-d[1], d[0]]) / length if length > 0 else np.array([1.0, 0.0])
        taken = [start, goal]  # then the parked agents drawn so far
        for _ in range(self.parked_agents):
            p = start + rng.uniform(1 / 3, 2 / 3) * d + rng.uniform(-2 * r, 2 * r) * normal
            if sc.is_free(p) and all(np.hypot(*(p - q)) > 2 * r + 0.05 for q in taken):
                taken.append(p)
        return np.array(taken[2:]).reshape(-1, 2)

    # ----------------------------------------------------------------- gym API
    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None):
        """Start an episode; see Starting State in the class docstring for ``options``."""
        super().reset(seed=seed)
        options = parse_reset_options(options, _RESET_OPTIONS, type(self).__name__)
        sc = self.scenario
        start, goal = self.draw_problem(self.np_random, options)
        self._goal = goal
        self._goal_norm = self.normalize(goal)
        if self.sensor is not None:
            self._goal_image = self.sensor.render(goal)
        if self.parked_fraction < 1.0 and self.np_random.random() >= self.parked_fraction:
            self._parked = np.zeros((0, 2))  # an episode without them
        else:
            self._parked = self.draw_parked(self.np_random, start, goal)
        agents = np.vstack([start[None], self._parked])
        # one agent restarts in the space of the previous episode (the same physics as a new one)
        if self._world is None or not self._world.restart(agents):
            self._world = World(sc.size, sc.boxes, agents, sc.agent_radius, self.substeps)
            for i in range(1, 1 + len(self._parked)):
                self._world.park(i)
        self._pos = start.copy()
        self._trail = [start.copy()]
        cost = float(sc.field.cost(start))
        return self._obs(), self._info(cost)

    def step(self, action):
        """Move the agent by ``action``; returns ``(obs, reward, terminated, False, info)``.

        ``reward`` is ``0.0`` when the step reaches the goal (``terminated``), ``-1.0`` otherwise.
        """
        world = self._world
        if world is None:
            raise RuntimeError("call reset() before step()")
        if type(action) is np.ndarray and action.dtype in _FLOAT_DTYPES and action.shape == (2,):
            x, y = action.tolist()  # exactly check_action's float64 values
            if not (math.isfinite(x) and math.isfinite(y)):
                check_action(action)  # raises, saying what is wrong
        else:
            x, y = check_action(action).tolist()
        x, y = min(max(x, -1.0), 1.0), min(max(y, -1.0), 1.0)  # np.clip of finite values
        if self.action_noise > 0:
            nx, ny = self.np_random.normal(0.0, self.action_noise, size=2).tolist()
            x, y = x + nx, y + ny
        scale = self.action_scale
        if len(self._parked):
            moves = np.zeros((1 + len(self._parked), 2))
            moves[0] = (x * scale, y * scale)
            pts = world.step(moves)[0][:, 0]
        else:
            pts = world.step_single(x * scale, y * scale)
        cost = self.scenario.field.peak_cost(pts)
        self._pos = pts[-1].copy()
        if self.render_mode is not None:
            self._trail.append(self._pos.copy())
        obs = self._obs()
        info = self._info(cost)
        terminated = bool(info["is_success"])
        if self.render_mode == "human":
            self.render()
        return obs, 0.0 if terminated else -1.0, terminated, False, info

    # ----------------------------------------------------------------- GoalEnv API
    @_dict_format_only
    def compute_reward(self, achieved_goal, desired_goal, info) -> Union[float, np.ndarray]:
        """``0`` where :meth:`compute_terminated` holds, ``-1`` elsewhere (single goals or batches).

        The reward :meth:`step` returns for the same goals (with panoramas, see Episode End);
        batches give ``float32`` arrays of the batch shape, as SB3's ``HerReplayBuffer`` expects.
        Defined with ``observation_format="dict"`` only: tools such as SB3's ``check_env`` take an
        env with ``compute_reward`` for a goal env, which needs ``Dict`` observations. On the flat
        format the same reward is ``-(not compute_terminated(...))``.
        """
        done = self.compute_terminated(achieved_goal, desired_goal, info)
        if isinstance(done, bool):
            return 0.0 if done else -1.0
        return done.astype(np.float32) - np.float32(1.0)

    def compute_cost(self, achieved_goal, desired_goal, info) -> Union[float, np.ndarray]:
        """The safety cost at the position of each achieved goal (vector observations only).

        The cost of a state does not depend on the goal, so relabelled transitions keep it;
        this recomputes it from the achieved goal alone (``desired_goal`` and ``info`` are
        unused), for buffers that relabel costs too. It is the cost of the step's last sub-step,
        at most the step's ``info["cost"]`` (the largest over its sub-steps). Panorama goals do
        not give positions: ``ValueError``; read ``info["cost"]`` instead.
        """
        if self.sensor is not None:
            raise ValueError(
                "compute_cost needs positions, which panorama goals do not give; use the stored info['cost']"
            )
        a = np.asarray(achieved_goal, dtype=np.float64)
        if a.shape[-1:] != (2,):
            raise ValueError(f"compute_cost: achieved_goal must have shape (..., 2), got {a.shape}")
        cost = self.scenario.field.cost(self.denormalize(np.clip(a, 0.0, 1.0)))
        return float(cost) if cost.ndim == 0 else cost.astype(np.float32)

    def compute_terminated(self, achieved_goal, desired_goal, info) -> Union[bool, np.ndarray]:
        """``True`` where the achieved goal is within ``goal_threshold`` world units of the desired goal.

        With panorama goals: ``True`` where the two images are identical (see Episode End).
        """
        if self.sensor is not None:
            a, d = np.asarray(achieved_goal), np.asarray(desired_goal)
            done = np.all(a == d, axis=tuple(range(-self._goal_ndim, 0)))
            return bool(done) if done.ndim == 0 else done
        diff = (np.asarray(achieved_goal, np.float64) - np.asarray(desired_goal, np.float64)) * self.scenario.size_arr
        done = np.linalg.norm(diff, axis=-1) <= self.goal_threshold
        return bool(done) if done.ndim == 0 else done

    def compute_truncated(self, achieved_goal, desired_goal, info) -> Union[bool, np.ndarray]:
        """Truncation is decided by the time limit alone: ``False`` everywhere."""
        a = np.asarray(achieved_goal)
        shape = a.shape[: a.ndim - self._goal_ndim]
        return False if shape == () else np.zeros(shape, dtype=bool)

    # ----------------------------------------------------------------- rendering
    def render(self) -> Optional[np.ndarray]:
        """The top-down frame (``rgb_array``), or ``None`` after showing it (``human``)."""
        if self.render_mode is not None and self._world is None:
            raise RuntimeError("call reset() before render()")
        return self._draw(
            self._pos[None], self._goal[None], [np.array(self._trail)],
            [self._waypoints] if self._waypoints is not None else None,
        )


__all__ = ["SafeNavigationEnv", "check_action"]
