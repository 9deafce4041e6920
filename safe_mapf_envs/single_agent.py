"""The single-agent goal-conditioned safe navigation environment (Gymnasium)."""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .rendering import HumanWindow, TopDownRenderer
from .scenario import NavigationScenario
from .sensors import PanoramaSensor, scene_for_layout
from .world import World


def check_action(action, shape: Tuple[int, ...] = (2,)) -> np.ndarray:
    """Return ``action`` as a float64 array, raising ``ValueError`` on a wrong shape, NaN or inf."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"action must be numeric with shape {shape}, got {action!r}") from exc
    if a.shape != shape:
        raise ValueError(f"action must have shape {shape}, got shape {a.shape}: {action!r}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {action!r}")
    return a


class SafeNavigationEnv(gym.Env):
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
    them. Out-of-range actions are clipped to ``[-1, 1]``; NaN, inf and wrong shapes raise
    ``ValueError``. Optional Gaussian noise (``action_noise``) is added after clipping.

    ## Observation Space
    A ``Dict`` in the goal-conditioned convention of Gymnasium-Robotics (usable with SB3's
    ``MultiInputPolicy`` and ``HerReplayBuffer``):

    - ``observation``: the agent's position divided by the world size, in ``[0, 1]^2``;
    - ``achieved_goal``: the same as ``observation``;
    - ``desired_goal``: the goal's position divided by the world size.

    All are ``float32``. Ground-truth positions in world units are in ``info["position"]`` and
    ``info["goal"]`` (for evaluation, never meant as policy input).

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
    ``-1`` on every step (Search on the Replay Buffer convention), so a value function counts
    the steps to the goal. :meth:`compute_reward` returns the same for any goal, vectors or
    images.

    ## Costs
    ``info["cost"]`` is the largest cost over the positions of the step's sub-steps:
    ``C = 2 - 2h/r`` for ``h <= r`` and 0 beyond (``cost_fn="linear"``, the paper's eq. 5),
    with ``h`` the exact distance from the agent's centre to the nearest obstacle boundary
    and ``r`` = ``cost_radius``. ``"cosine"`` and ``"constant"`` profiles are available. The
    outer boundary confines the agent but costs nothing unless ``boundary_cost=True``.

    ## Starting State
    Start and goal are sampled uniformly in the free space (positions whose distance to every
    obstacle is at least the agent radius). ``reset(options=...)`` accepts:

    - ``{"start": (x, y), "goal": (x, y)}`` to pin a problem (world units; either key alone works);
    - ``{"goal_distance": (lo, hi)}`` to sample a goal whose ground-truth geodesic distance from
      the start lies in the band.

    With ``max_start_cost`` set, sampled starts are restricted to positions whose cost is at
    most that value.

    ## Episode End
    ``terminated`` when the agent's centre is within ``goal_threshold`` units of the goal;
    ``truncated`` after ``max_episode_steps`` (20 for the registered ids, as in the paper; pass
    ``max_episode_steps=...`` to ``gymnasium.make`` for longer evaluation episodes).

    Termination is always decided from ground truth. :meth:`compute_terminated` sees only the
    goals it is given: with vector goals it applies the same ``goal_threshold`` rule; with
    image goals it cannot recover positions, so it returns ``True`` exactly where the two
    panoramas are identical pixel for pixel (a relabelled goal that is the achieved panorama
    itself). Near the goal, ``step`` may terminate while the images still differ; use
    ``info["is_success"]`` to evaluate.

    ## Arguments
    ``gymnasium.make("SafeCentralObstacle-v0", render_mode=None, **kwargs)`` with kwargs:

    - ``layout``: map name or layout object (set by the registered id);
    - ``agent_radius`` (0.5), ``cost_radius`` (map default; 10 on CentralObstacle),
      ``cost_fn`` ("linear"), ``boundary_cost`` (False);
    - ``goal_threshold`` (1.0), ``action_noise`` (0.0, std of Gaussian noise on the action),
      ``substeps`` (4);
    - ``max_start_cost`` (None), ``goal_distance`` (None: default band for sampled goals);
    - ``obs_type`` ("vector" or "panorama"), ``action_scale`` (1.0; world units per unit of
      action), ``sensor_kwargs`` (None: :class:`~safe_mapf_envs.sensors.PanoramaSensor`
      arguments for panoramas).

    The apartment ids (``SafeApartment0-v0`` .. ``SafeApartment3-v0``) are in metres with
    ``agent_radius=0.2``, ``action_scale=0.25``, ``goal_threshold=0.5``, cost radius 1 and
    panorama observations; ``SafeCentralObstacleVisual-v0`` is the 2D benchmark seen in
    panoramas.

    ``render_mode="rgb_array"`` returns a top-down image with the cost heat map, obstacles,
    agent, goal, trail and planned waypoints (see :meth:`set_waypoints`); ``"human"`` shows it
    in a matplotlib window and needs a display (``RuntimeError`` otherwise).

    ## Version History
    - v0: initial release.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

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
        goal_distance: Optional[Tuple[float, float]] = None,
        obs_type: str = "vector",
        action_scale: float = 1.0,
        sensor_kwargs: Optional[Dict[str, Any]] = None,
    ) -> None:
        if obs_type not in ("vector", "panorama"):
            raise ValueError(f"obs_type must be 'vector' or 'panorama', got {obs_type!r}")
        if not np.isfinite(action_scale) or action_scale <= 0:
            raise ValueError(f"action_scale must be a positive number, got {action_scale!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps!r}")
        if not np.isfinite(action_noise) or action_noise < 0:
            raise ValueError(f"action_noise must be >= 0, got {action_noise!r}")
        if not np.isfinite(goal_threshold) or goal_threshold <= 0:
            raise ValueError(f"goal_threshold must be > 0, got {goal_threshold!r}")
        self.scenario = NavigationScenario(
            layout, agent_radius=agent_radius, cost_radius=cost_radius, cost_fn=cost_fn, boundary_cost=boundary_cost
        )
        self.render_mode = render_mode
        self.goal_threshold = float(goal_threshold)
        self.action_noise = float(action_noise)
        self.substeps = int(substeps)
        self.max_start_cost = max_start_cost
        self.goal_distance = goal_distance
        self._inv_size = 1.0 / self.scenario.size_arr
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.obs_type = obs_type
        self.action_scale = float(action_scale)
        self.sensor: Optional[PanoramaSensor] = None
        if obs_type == "panorama":
            self.sensor = PanoramaSensor(scene_for_layout(self.scenario.layout), **(sensor_kwargs or {}))
            pos_space = spaces.Box(0, 255, shape=self.sensor.shape, dtype=np.uint8)
        else:
            pos_space = spaces.Box(0.0, 1.0, shape=(2,), dtype=np.float32)
        self._goal_ndim = len(pos_space.shape)
        self._goal_image: Optional[np.ndarray] = None
        self.observation_space = spaces.Dict(
            {"observation": pos_space, "achieved_goal": pos_space, "desired_goal": pos_space}
        )
        self._world: Optional[World] = None
        self._pos = np.zeros(2)
        self._goal = np.zeros(2)
        self._trail: list = []
        self._waypoints: Optional[np.ndarray] = None
        self._renderer: Optional[TopDownRenderer] = None
        self._window: Optional[HumanWindow] = HumanWindow(type(self).__name__) if render_mode == "human" else None

    # ----------------------------------------------------------------- properties
    @property
    def field(self):
        """The :class:`~safe_mapf_envs.cost.ObstacleField` (obstacles, cost function)."""
        return self.scenario.field

    @property
    def world_size(self) -> Tuple[float, float]:
        """World extent ``(width, height)`` in units; observations are positions divided by it."""
        return self.scenario.size

    @property
    def position(self) -> np.ndarray:
        """Ground-truth agent position (world units)."""
        return self._pos.copy()

    @property
    def goal(self) -> np.ndarray:
        """Ground-truth goal position (world units)."""
        return self._goal.copy()

    # ----------------------------------------------------------------- helpers
    def normalize(self, positions: np.ndarray) -> np.ndarray:
        """World-unit positions ``(..., 2)`` to observations in ``[0, 1]`` (float32)."""
        return (np.asarray(positions, dtype=np.float64) * self._inv_size).astype(np.float32)

    def denormalize(self, observations: np.ndarray) -> np.ndarray:
        """Observations in ``[0, 1]`` back to world-unit positions."""
        return np.asarray(observations, dtype=np.float64) * self.scenario.size_arr

    def sample_states(self, n: int, rng: Optional[np.random.Generator] = None, max_cost: Optional[float] = None) -> np.ndarray:
        """``n`` random free positions (world units), shape ``(n, 2)``."""
        return self.scenario.sample_states(n, rng if rng is not None else self.np_random, max_cost=max_cost)

    def geodesic_distance(self, a, b) -> np.ndarray:
        """Ground-truth shortest collision-free path length between world points (evaluation only)."""
        return self.scenario.geodesic_distance(a, b)

    def set_waypoints(self, waypoints: Optional[np.ndarray]) -> None:
        """Planned waypoints (world units, ``(K, 2)``) to draw in rendered frames; ``None`` clears them."""
        self._waypoints = None if waypoints is None else np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)

    def _obs(self) -> Dict[str, np.ndarray]:
        if self.sensor is not None:
            img = self.sensor.render(self._pos)
            return {"observation": img, "achieved_goal": img.copy(), "desired_goal": self._goal_image.copy()}
        p = self.normalize(self._pos)
        return {"observation": p, "achieved_goal": p.copy(), "desired_goal": self.normalize(self._goal)}

    def _info(self, cost: float) -> Dict[str, Any]:
        dist = float(np.linalg.norm(self._pos - self._goal))
        return {
            "cost": cost,
            "position": self._pos.copy(),
            "goal": self._goal.copy(),
            "distance_to_goal": dist,
            "is_success": dist <= self.goal_threshold,
        }

    # ----------------------------------------------------------------- gym API
    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"start", "goal", "goal_distance"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; expected 'start', 'goal', 'goal_distance'")
        sc = self.scenario
        rng = self.np_random
        if options.get("start") is not None:
            start = sc.check_position(options["start"], "start")
        else:
            start = sc.sample_states(1, rng, max_cost=self.max_start_cost)[0]
        band = options.get("goal_distance", self.goal_distance)
        if options.get("goal") is not None:
            goal = sc.check_position(options["goal"], "goal")
        elif band is not None:
            goal = sc.sample_goal_in_band(start, band, rng)
        else:
            goal = sc.sample_states(1, rng)[0]
        self._goal = goal
        if self.sensor is not None:
            self._goal_image = self.sensor.render(goal)
        self._world = World(sc.size, sc.boxes, start[None], sc.agent_radius, self.substeps)
        self._pos = start.copy()
        self._trail = [start.copy()]
        cost = float(sc.field.cost(start))
        return self._obs(), self._info(cost)

    def step(self, action):
        if self._world is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action)
        a = np.clip(a, -1.0, 1.0)
        if self.action_noise > 0:
            a = a + self.np_random.normal(0.0, self.action_noise, size=2)
        trace, _ = self._world.step(a[None] * self.action_scale)
        pts = trace[:, 0]
        cost = float(self.scenario.field.cost(pts).max())
        self._pos = pts[-1].copy()
        if self.render_mode is not None:
            self._trail.append(self._pos.copy())
        obs = self._obs()
        info = self._info(cost)
        terminated = bool(info["is_success"])
        if self.render_mode == "human":
            self.render()
        return obs, -1.0, terminated, False, info

    # ----------------------------------------------------------------- GoalEnv API
    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """Reward for (batches of) achieved/desired goals: -1 everywhere, as returned by :meth:`step`."""
        a = np.asarray(achieved_goal)
        shape = a.shape[: a.ndim - self._goal_ndim]
        if shape == ():
            return -1.0
        return -np.ones(shape, dtype=np.float32)

    def compute_terminated(self, achieved_goal, desired_goal, info) -> np.ndarray:
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

    def compute_truncated(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """Truncation is decided by the time limit alone: ``False`` everywhere."""
        a = np.asarray(achieved_goal)
        shape = a.shape[: a.ndim - self._goal_ndim]
        return False if shape == () else np.zeros(shape, dtype=bool)

    # ----------------------------------------------------------------- rendering
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gymnasium.make")
            return None
        if self._renderer is None:
            self._renderer = TopDownRenderer(self.scenario.field, agent_radius=self.scenario.agent_radius)
        img = self._renderer.render(
            self._pos[None], goals=self._goal[None], trails=[np.array(self._trail)],
            waypoints=[self._waypoints] if self._waypoints is not None else None,
        )
        if self._window is not None:
            self._window.show(img)
            return None
        return img

    def close(self):
        if self._window is not None:
            self._window.close()
            self._window = None
        self._renderer = None


__all__ = ["SafeNavigationEnv", "check_action"]
