"""A native vector env: ``num_envs`` single-agent episodes in one physics space, stepped in one batch.

``gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` builds
:class:`SafeNavigationVectorEnv` for the ids with vector observations. Its sub-envs are the
single-agent env exactly (same spaces, rewards, costs, termination, time limit, reset options
and seeding: ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i``, as ``SyncVectorEnv`` does),
but their agents share one pymunk space in which they pass through each other, so one physics
step, one cost query and one observation update serve all of them. Episodes end and restart
independently, with Gymnasium's next-step autoreset.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .checks import check_count, parse_reset_options
from .formats import flatten_observation
from .single_agent import _RESET_OPTIONS, SafeNavigationEnv
from .world import World

_INFO_KEYS = ("cost", "position", "goal", "distance_to_goal", "is_success")


class SafeNavigationVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~safe_mapf_envs.single_agent.SafeNavigationEnv` stepped as one.

    Args:
        num_envs: number of sub-environments.
        max_episode_steps: each sub-env's time limit (``gymnasium.make_vec`` passes the id's).
        render_mode: only ``None`` (render the single-agent env instead).
        **kwargs: the single-agent env's keyword arguments (``layout``, ``goal_distance``,
            ``observation_format``, ...); vector observations only.

    ``reset(seed=s, options=...)`` resets every sub-env (``options`` as the single env's, for all
    of them). ``step(actions)`` takes ``(num_envs, 2)`` actions; NaN, inf or a wrong shape raise
    ``ValueError``, out-of-range values are clipped. ``infos`` holds ``cost``, ``position``,
    ``goal``, ``distance_to_goal`` and ``is_success`` as arrays over the sub-envs.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int, max_episode_steps: Optional[int] = None,
                 render_mode: Optional[str] = None, **kwargs: Any) -> None:
        self.num_envs = check_count(num_envs, "num_envs", 1)
        if max_episode_steps is not None:
            max_episode_steps = check_count(max_episode_steps, "max_episode_steps", 1)
        self.max_episode_steps = max_episode_steps
        if render_mode is not None:
            raise ValueError(f"the native vector env does not render (render_mode must be None, got {render_mode!r}); "
                             "render a single env, or use vectorization_mode='sync'")
        #: the single-agent env whose settings, spaces and goal methods every sub-env shares
        self.env = SafeNavigationEnv(**kwargs)
        if self.env.parked_agents:
            raise ValueError("the native vector env has no parked agents (parked_agents must be 0); use "
                             "gymnasium.make_vec(..., vectorization_mode='sync')")
        if self.env.sensor is not None:
            raise ValueError("the native vector env builds vector observations; for panoramas use "
                             "gymnasium.make_vec(..., vectorization_mode='sync')")
        self.render_mode = None
        self.single_observation_space = self.env.observation_space
        self.single_action_space = self.env.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n = self.num_envs
        self._rngs: List[np.random.Generator] = [seeding.np_random()[0] for _ in range(n)]
        self._world: Optional[World] = None
        self._pos = np.zeros((n, 2))
        self._goals = np.zeros((n, 2))
        self._elapsed = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=bool)

    # ----------------------------------------------------------------- helpers
    def _observe(self) -> Union[Dict[str, np.ndarray], np.ndarray]:
        p = self.env.normalize(self._pos)
        obs = {"observation": p, "achieved_goal": p.copy(), "desired_goal": self.env.normalize(self._goals)}
        return flatten_observation(obs) if self.env.observation_format == "flat" else obs

    def _infos(self, cost: np.ndarray) -> Dict[str, Any]:
        dist = np.sqrt(((self._pos - self._goals) ** 2).sum(-1))
        values = {"cost": cost, "position": self._pos.copy(), "goal": self._goals.copy(),
                  "distance_to_goal": dist, "is_success": dist <= self.env.goal_threshold}
        infos: Dict[str, Any] = {}
        everyone = np.ones(self.num_envs, dtype=bool)
        for k in _INFO_KEYS:
            infos[k] = values[k]
            infos[f"_{k}"] = everyone
        return infos

    def _restart(self, which: Sequence[int], options: Dict[str, Any]) -> None:
        """New problems for the sub-envs ``which``, each from its own generator."""
        assert self._world is not None
        for i in which:
            start, goal = self.env.draw_problem(self._rngs[i], options)
            self._pos[i], self._goals[i] = start, goal
            self._world.place(i, start)
            self._elapsed[i] = 0

    # ----------------------------------------------------------------- vector API
    def reset(self, *, seed: Optional[Union[int, Sequence[Optional[int]]]] = None,
              options: Optional[Dict[str, Any]] = None) -> Tuple[Any, Dict[str, Any]]:
        """Reset every sub-env; an int ``seed`` seeds sub-env ``i`` with ``seed + i``."""
        n = self.num_envs
        if seed is None:
            seeds: List[Optional[int]] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed must be an int or one seed per sub-env ({n}), got {len(seeds)}")
        for i, s in enumerate(seeds):
            if s is not None:
                self._rngs[i] = seeding.np_random(s)[0]
        opts = parse_reset_options(options, _RESET_OPTIONS, type(self).__name__)
        sc = self.env.scenario
        # a new space per reset of all sub-envs; the agents of the sub-envs pass through each other
        self._world = World(sc.size, sc.boxes, np.zeros((n, 2)), sc.agent_radius, self.env.substeps,
                            agent_collisions=False)
        self._restart(range(n), opts)
        self._autoreset[:] = False
        return self._observe(), self._infos(sc.field.cost(self._pos))

    def step(self, actions: Any) -> Tuple[Any, np.ndarray, np.ndarray, np.ndarray, Dict[str, Any]]:
        """Step every sub-env; those that ended on the previous step restart instead (next-step autoreset)."""
        if self._world is None:
            raise RuntimeError("call reset() before step()")
        n = self.num_envs
        try:
            raw = np.asarray(actions)
            a = raw.astype(np.float64) if raw.dtype.kind in "fiub" else None
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != (n, 2) or not np.isfinite(a).all():
            raise ValueError(f"actions must be a ({n}, 2) array of finite real numbers, got "
                             f"{'shape ' + str(np.shape(actions)) if a is not None else repr(actions)}")
        a = np.clip(a, -1.0, 1.0)
        env = self.env
        restart = np.flatnonzero(self._autoreset)
        moving = ~self._autoreset
        if env.action_noise > 0:
            for i in np.flatnonzero(moving):  # each sub-env's own generator, as the single env draws
                a[i] = a[i] + self._rngs[i].normal(0.0, env.action_noise, size=2)
        a[~moving] = 0.0
        trace, _ = self._world.step(a * env.action_scale)
        cost = env.scenario.field.cost(trace).max(axis=0)
        self._pos = trace[-1].copy()
        self._elapsed[moving] += 1
        if len(restart):
            self._restart(restart.tolist(), {})
            cost[restart] = env.scenario.field.cost(self._pos[restart])
        dist = np.sqrt(((self._pos - self._goals) ** 2).sum(-1))
        terminated = (dist <= env.goal_threshold) & moving
        truncated = np.zeros(n, dtype=bool)
        if self.max_episode_steps is not None:
            truncated = (self._elapsed >= self.max_episode_steps) & moving
        reward = np.where(terminated, 0.0, -1.0)
        reward[restart] = 0.0
        self._autoreset = terminated | truncated
        return self._observe(), reward, terminated, truncated, self._infos(cost)

    def close_extras(self, **kwargs: Any) -> None:
        self._world = None


__all__ = ["SafeNavigationVectorEnv"]
