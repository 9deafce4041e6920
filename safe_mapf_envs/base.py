"""What the single- and multi-agent navigation environments share.

:class:`NavigationEnvBase` holds the map (a :class:`~safe_mapf_envs.scenario.NavigationScenario`),
the checked constructor arguments, the panorama sensor, the top-down renderer and the helpers
both environments offer: :meth:`~NavigationEnvBase.normalize`,
:meth:`~NavigationEnvBase.sample_states`, :meth:`~NavigationEnvBase.geodesic_distance` and
:meth:`~NavigationEnvBase.observations_at`. The Gymnasium and PettingZoo classes add their own
API on top (``SafeNavigationEnv(NavigationEnvBase, gymnasium.Env)``,
``SafeMultiNavigationEnv(NavigationEnvBase, ParallelEnv)``).

Reset options follow one rule in both environments: known keys are validated, unknown keys are
ignored with a ``UserWarning`` that names them (see
:func:`~safe_mapf_envs.checks.parse_reset_options`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import gymnasium
import numpy as np

from .checks import check_count, check_goal_distance, check_number, check_render_mode, show
from .cost import ObstacleField
from .formats import check_observation_format
from .rendering import HumanWindow, TopDownRenderer
from .scenario import NavigationScenario
from .sensors import PanoramaSensor, scene_for_layout

#: Render modes of both environments.
RENDER_MODES = ("rgb_array", "human")


@dataclass(frozen=True)
class StepBound:
    """A lower bound of the steps between vector observations, as a plain (picklable) function of
    ``(obs_a[N, 2], obs_b[M, 2]) -> (N, M)``: the straight-line distance less ``goal_threshold``
    over the longest step (an action is clipped to ``[-1, 1]`` per axis, so a step moves at most
    ``sqrt(2) * action_scale``). What :meth:`NavigationEnvBase.min_steps` computes, without the env.

    Attributes:
        size: the world's extent ``(width, height)`` in units (observations are positions over it).
        goal_threshold: how near a goal counts as reached (units).
        action_scale: the longest move per step along each axis (units).
    """

    size: Tuple[float, float]
    goal_threshold: float
    action_scale: float

    def __call__(self, obs_a: np.ndarray, obs_b: np.ndarray) -> np.ndarray:
        size = np.asarray(self.size, dtype=np.float64)
        a = np.asarray(obs_a, dtype=np.float64).reshape(-1, 2) * size
        b = np.asarray(obs_b, dtype=np.float64).reshape(-1, 2) * size
        gap = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)) - self.goal_threshold
        return np.maximum(gap, 0.0) / (np.sqrt(2.0) * self.action_scale)


class NavigationEnvBase:
    """The map, settings, sensor, renderer and helpers of a navigation environment (a mixin).

    Subclasses call :meth:`_setup` at the start of ``__init__`` and :meth:`_open_window` at
    its end (so that a failed check leaves no window behind), and keep ground truth in world
    units; they provide ``np_random`` (Gymnasium and PettingZoo environments do).
    """

    #: Observation types this class builds; subclasses extend it with their own.
    obs_types: Tuple[str, ...] = ("vector", "panorama")

    scenario: NavigationScenario
    sensor: Optional[PanoramaSensor]
    np_random: np.random.Generator

    def _setup(
        self,
        layout: Any,
        render_mode: Optional[str],
        *,
        obs_type: str,
        agent_radius: float,
        cost_radius: Optional[float],
        cost_fn: str,
        boundary_cost: bool,
        goal_threshold: float,
        action_noise: float,
        substeps: int,
        max_start_cost: Optional[float],
        goal_distance: Union[None, str, Tuple[float, float]],
        action_scale: float,
        sensor_kwargs: Optional[Dict[str, Any]],
        observation_format: str = "dict",
    ) -> None:
        """Check the shared constructor arguments and build the scenario and sensor."""
        self.render_mode = check_render_mode(render_mode, RENDER_MODES)
        self.observation_format = check_observation_format(observation_format)
        if obs_type not in self.obs_types:
            raise ValueError(
                f"obs_type must be one of {list(self.obs_types)} for {type(self).__name__}, got {show(obs_type)}"
            )
        self.obs_type = obs_type
        self.substeps = check_count(substeps, "substeps", 1)
        self.action_noise = check_number(action_noise, "action_noise")
        self.goal_threshold = check_number(goal_threshold, "goal_threshold", strict=True)
        self.action_scale = check_number(action_scale, "action_scale", strict=True)
        self.max_start_cost = None if max_start_cost is None else check_number(max_start_cost, "max_start_cost")
        self.goal_distance = check_goal_distance(goal_distance)
        self.scenario = NavigationScenario(
            layout, agent_radius=agent_radius, cost_radius=cost_radius, cost_fn=cost_fn, boundary_cost=boundary_cost
        )
        self._inv_size = 1.0 / self.scenario.size_arr
        self.sensor = None
        if obs_type == "panorama":
            self.sensor = PanoramaSensor(scene_for_layout(self.scenario.layout), **(sensor_kwargs or {}))
        self._renderer: Optional[TopDownRenderer] = None
        self._window: Optional[HumanWindow] = None

    def _open_window(self) -> None:
        """Open the window of the ``human`` render mode (it warns and shows nothing without a display)."""
        if self.render_mode == "human" and self._window is None:
            self._window = HumanWindow(type(self).__name__)

    # ----------------------------------------------------------------- properties
    @property
    def field(self) -> ObstacleField:
        """The :class:`~safe_mapf_envs.cost.ObstacleField` (obstacles, cost function)."""
        return self.scenario.field

    @property
    def world_size(self) -> Tuple[float, float]:
        """World extent ``(width, height)`` in units; observations are positions divided by it."""
        return self.scenario.size

    # ----------------------------------------------------------------- helpers
    def normalize(self, positions: np.ndarray) -> np.ndarray:
        """World-unit positions ``(..., 2)`` to observations in ``[0, 1]`` (float32)."""
        return (np.asarray(positions, dtype=np.float64) * self._inv_size).astype(np.float32)

    def denormalize(self, observations: np.ndarray) -> np.ndarray:
        """Observations in ``[0, 1]`` back to world-unit positions."""
        return np.asarray(observations, dtype=np.float64) * self.scenario.size_arr

    def min_steps(self, obs_a: np.ndarray, obs_b: np.ndarray) -> np.ndarray:
        """A lower bound of the steps from each vector observation of ``obs_a`` to within
        ``goal_threshold`` of each of ``obs_b``: ``(N, M)``, the straight-line distance less the
        threshold over the longest step (an action is clipped to ``[-1, 1]`` per axis, so a step
        moves at most ``sqrt(2) * action_scale``). No walls are looked at, so it costs a distance
        matrix; a planner reads its critics only where this bound is short
        (:class:`~agents.search.graph.build.NodePairwise`'s ``bound``). Vector observations only."""
        return self.step_bound()(obs_a, obs_b)

    def step_bound(self) -> StepBound:
        """:meth:`min_steps` as a :class:`StepBound` of this env's world, to hand to other processes.
        Vector observations only."""
        if self.obs_type != "vector":
            raise ValueError(f"min_steps needs vector observations (positions); this env observes {self.obs_type}s")
        width, height = self.world_size
        return StepBound((float(width), float(height)), float(self.goal_threshold), float(self.action_scale))

    def sample_states(
        self, n: int, rng: Optional[np.random.Generator] = None, max_cost: Optional[float] = None
    ) -> np.ndarray:
        """``n`` random free positions (world units), shape ``(n, 2)``; ``n`` must be an integer >= 0.

        Args:
            n: how many.
            rng: the generator; default the environment's ``np_random``.
            max_cost: if given, only positions whose cost is at most this value.
        """
        return self.scenario.sample_states(n, rng if rng is not None else self.np_random, max_cost=max_cost)

    def sample_narrow_states(
        self, n: int, rng: Optional[np.random.Generator] = None, bridge: Optional[float] = None
    ) -> np.ndarray:
        """``n`` random free positions in narrow passages (the bridge test, see
        :meth:`~safe_mapf_envs.scenario.NavigationScenario.sample_narrow_states`), shape ``(n, 2)``."""
        return self.scenario.sample_narrow_states(n, rng if rng is not None else self.np_random, bridge=bridge)

    def sample_narrow_crossings(
        self, n: int, reach: Tuple[float, float], rng: Optional[np.random.Generator] = None,
        bridge: Optional[float] = None,
    ) -> Tuple[np.ndarray, np.ndarray]:
        """``n`` start-goal pairs through narrow passages, ``reach`` (world units) on either side
        (see :meth:`~safe_mapf_envs.scenario.NavigationScenario.sample_narrow_crossings`)."""
        return self.scenario.sample_narrow_crossings(n, rng if rng is not None else self.np_random, reach,
                                                     bridge=bridge)

    def geodesic_distance(self, a, b) -> np.ndarray:
        """Ground-truth shortest collision-free path length from world point ``a`` to each of ``b``.

        For evaluation only. ``b`` may be ``(..., 2)``; points outside the world or inside an
        obstacle raise ``ValueError``.
        """
        return self.scenario.geodesic_distance(a, b)

    def observations_at(self, states) -> np.ndarray:
        """The observation an agent would receive at each world position in ``states``.

        Args:
            states: world positions, shape ``(..., 2)``.

        Returns:
            For vector observations the normalised positions, ``float32`` of shape
            ``(..., 2)``; for panoramas the ``uint8`` images ``(..., 4, S, S, 4)``, rendered in
            one batch. This is the ``observation`` entry (and the ``desired_goal`` entry of a
            goal there); in the multi-agent env the panoramas show the scene without other
            agents, as goal panoramas do, and the ``neighbors`` entry is not included.
        """
        p = self.scenario._as_points(states, "states")
        if self.sensor is None:
            return self.normalize(p)
        lead = p.shape[:-1]
        flat = p.reshape(-1, 2)
        if len(flat) == 0:
            return np.zeros((*lead, *self.sensor.shape), dtype=np.uint8)
        return self.sensor.render(flat).reshape(*lead, *self.sensor.shape)

    # ----------------------------------------------------------------- rendering
    def _draw(
        self,
        positions: np.ndarray,
        goals: np.ndarray,
        trails: Sequence[np.ndarray],
        waypoints: Optional[Sequence[Optional[np.ndarray]]],
        collisions: Optional[Sequence[np.ndarray]] = None,
        parked: Optional[np.ndarray] = None,
    ) -> Optional[np.ndarray]:
        """Draw a top-down frame; return it (``rgb_array``) or show it (``human``)."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' when making the env"
            )
            return None
        if self._renderer is None:
            self._renderer = TopDownRenderer(self.scenario.field, agent_radius=self.scenario.agent_radius)
        img = self._renderer.render(
            positions, goals=goals, trails=trails, waypoints=waypoints, collisions=collisions, parked=parked
        )
        if self._window is not None:
            self._window.show(img)
            return None
        return img

    def close(self) -> None:
        """Close the window of the ``human`` render mode, if any."""
        if self._window is not None:
            self._window.close()
            self._window = None
        self._renderer = None


__all__ = ["NavigationEnvBase", "RENDER_MODES"]
