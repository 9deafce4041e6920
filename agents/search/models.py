"""Adapters from trained models to the search: policy and distance functions, graph nodes, defaults.

The functions here turn a goal-conditioned SB3 model into what the planner and the controller
call (``policy(obs, goals)``, ``distance(obs, goals)``), draw graph nodes from a replay buffer or
an env, check that a critic and a driver belong together, and pick the controller defaults that
suit the model's observations (vectors or panoramas). This module does not import torch.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, Mapping, Optional

import numpy as np

#: ``policy(obs[B, ...], goal[B, ...]) -> actions[B, 2]``
PolicyFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
#: ``distance(obs[B, ...], goal[B, ...]) -> [B]``
DistanceFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def policy_fn(model: Any, deterministic: bool = True) -> PolicyFn:
    """``policy(obs[B], goal[B]) -> actions[B, 2]`` from a goal-conditioned SB3 model."""

    def act(obs: np.ndarray, goals: np.ndarray) -> np.ndarray:
        batch = {"observation": obs, "achieved_goal": obs, "desired_goal": goals}
        return model.predict(batch, deterministic=deterministic)[0]

    return act


def distance_fn(model: Any, aggregate: str = "max") -> DistanceFn:
    """``distance(obs[B], goal[B]) -> [B]`` predicted steps (pessimistic ensemble by default)."""

    def dist(obs: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return model.distance(obs, goals, aggregate=aggregate)

    return dist


def buffer_observations(replay_buffer: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` distinct observations drawn from an SB3 (dict) replay buffer's stored transitions."""
    stored = replay_buffer.observations
    obs = stored["observation"] if isinstance(stored, Mapping) else stored
    size = replay_buffer.buffer_size if getattr(replay_buffer, "full", False) else replay_buffer.pos
    flat = np.asarray(obs[:size]).reshape(-1, *np.shape(obs)[2:])
    if len(flat) < n:
        raise ValueError(f"the replay buffer holds {len(flat)} observations, fewer than the {n} graph nodes asked for")
    return flat[np.sort(rng.choice(len(flat), size=n, replace=False))]


def env_observations(env_id: str, n: int, seed: int = 0) -> np.ndarray:
    """Observations at ``n`` random free states of the registered env ``env_id`` (seeded)."""
    import gymnasium as gym

    import safe_mapf_envs  # noqa: F401  (registers the ids)

    env = gym.make(env_id)
    try:
        u: Any = env.unwrapped
        states = u.sample_states(n, np.random.default_rng(seed))
        return np.asarray(u.observations_at(states))
    finally:
        env.close()


#: default waypoint reach threshold (predicted steps) of critics of vector observations
REACH_THRESHOLD = 2.0
#: the same for critics of panoramas: their predicted distance to a goal already within the
#: env's goal radius is below 2 in only 66-94% of cases (median 1.3-1.8, 95th percentile 2.2-3.7,
#: measured on the shipped apartment agents), and an agent whose waypoint is never judged
#: reached hovers next to it until the unstick rule frees it
PANORAMA_REACH_THRESHOLD = 3.0


def check_models(critic: Any, driver: Any) -> None:
    """``ValueError`` unless ``critic`` can annotate a graph and ``driver`` is a model of the same env.

    The critic needs ``pairwise`` distances and costs (a :class:`~agents.SafeGoalTD3`). Models
    that name their env (``env_id``) must name the same one, and models with an observation
    space must have the same.
    """
    if not callable(getattr(critic, "pairwise", None)):
        raise ValueError(f"the critic must give pairwise distances and costs (a SafeGoalTD3 model); a "
                         f"{type(critic).__name__} has no pairwise(): it can only drive, as driver= next to a "
                         "SafeGoalTD3 critic (with distance_model=the critic to judge waypoints reached)")
    if driver is None:
        return
    ids = [getattr(m, "env_id", None) for m in (critic, driver)]
    if None not in ids and ids[0] != ids[1]:
        raise ValueError(f"the critic was trained on {ids[0]} and the driver on {ids[1]}: both must be of one env")
    spaces_ = [getattr(m, "observation_space", None) for m in (critic, driver)]
    if None not in spaces_ and spaces_[0] != spaces_[1]:
        raise ValueError(f"the critic and the driver observe different spaces ({spaces_[0]} and {spaces_[1]}): "
                         "both must be models of one env")


def _reads_images(model: Any) -> bool:
    """Whether ``model`` observes images (its observation space, or that space's ``observation`` entry)."""
    from gymnasium import spaces

    from ..encoders import is_image_space

    space = getattr(model, "observation_space", None)
    if isinstance(space, spaces.Dict) and "observation" in space.spaces:
        space = space["observation"]
    return space is not None and is_image_space(space)


def default_reach_threshold(model: Any) -> float:
    """:data:`PANORAMA_REACH_THRESHOLD` for a model of image observations, else :data:`REACH_THRESHOLD`."""
    return PANORAMA_REACH_THRESHOLD if _reads_images(model) else REACH_THRESHOLD


#: controller options for agents of panoramas (see :class:`WaypointController`): a waypoint also
#: counts as reached below its own predicted distance to itself plus half a step, or once the
#: agent has hovered within 1.5 steps of the threshold for 6 steps without coming closer. On
#: Apartment0 (5 agents, easy problems, 20 problems) ours' mean cost fell from 21.5 to 14.7. An
#: agent that comes no closer to its target for 20 steps counts as stuck (it took the target's
#: panorama for another place's and hovers there). A stuck agent hands its leg to the fallback
#: policy (where there is one) the first time it is found stuck on it, and asks for a new plan
#: the next time (``skip_after=1``; the controller's default, 2, spends two rounds of random
#: escapes on each): failed agents of Apartment3's 10-agent Table II runs spent 37% of their
#: steps in escapes and fallback legs. Apartment3, seed 1, 10 agents, 50 medium and 50 hard
#: problems: success 98% / 90% -> 100% / 92%, mean largest cost 85 / 168 -> 69 / 131. An agent
#: found stuck more than 4 times in an episode sidesteps from then on (``sidestep_after=4``): on
#: the validation problems (seed 1, 50 per difficulty; Apartment0 5 agents, the others 10) 599 of
#: 600 runs arrived against 596 (561 runs unchanged; mean largest cost of the runs that arrived
#: both ways 53.7 -> 52.8). By the threshold, a waypoint counts as reached only where the agent is
#: also within 3 steps of the waypoint's own predicted distance to the next target, or comes no
#: closer to the waypoint (``advance_slack=3``, :mod:`agents.search.advance`): on the validation
#: problems (seeds 1 and 2, as above) 1188 of 1200 runs arrived against 1190, and the mean largest
#: cost of the runs that arrived both ways fell from 52.00 to 47.33 (95% bootstrap interval of the
#: change [-6.29, -3.13]; with ``advance_slack=2``: 1186 arrived, 51.93 -> 45.15). An agent whose
#: leg to the goal is handed to the fallback policy goes back to its last waypoint first
#: (``retreat="goal"``): on the same validation problems 1189 of 1200 runs arrived either way (101
#: runs changed), and the mean largest cost fell from 47.20 to 46.71 (interval [-0.87, -0.17]); going
#: back on every leg (``"any"``): 1189 arrived (3 lost, 3 gained, 385 changed), 47.07 -> 46.91
#: ([-1.04, +0.74]). A leg whose target the driving agent's critic puts beyond 14 steps at its start
#: (twice the graph's ``d_max``: the graph's critic made it one edge, and the driver will not go
#: there) goes to the fallback policy at once (``fallback_beyond=14``): on the validation problems
#: (seeds 1 and 2, as above) 1190 of 1200 runs arrived against 1189 (none lost, 244 changed) and the
#: mean largest cost fell from 45.21 to 43.64 ([-2.28, -0.87]); with the narrow replans of
#: ``SearchPolicy(ban_detour=0)`` as well, 1191 arrived and 45.11 -> 43.30 ([-2.69, -0.96]).
PANORAMA_CONTROLLER_OPTIONS: Dict[str, Any] = {"self_margin": 0.5, "settle_patience": 6, "progress_patience": 20,
                                               "skip_after": 1, "sidestep_after": 4,
                                               "advance_slack": 3.0, "retreat": "goal", "fallback_beyond": 14.0}


def default_hold(model: Any) -> str:
    """``"order"`` for a model of image observations, else ``"waits"`` (see :class:`SearchPolicy`'s ``hold``).

    Panorama agents are often much slower than planned (escapes, fallbacks, replans): in the
    plan's order a late agent delays the others instead of meeting them. Vector agents keep to
    the plan's times, and waiting for the plan's order only adds cost there (CentralObstacle,
    hard problems, 20 agents, 50 problems: ours' mean largest cost 47.4 in the plan's order
    against 27.4 on the clock, both always successful).
    """
    return "order" if _reads_images(model) else "waits"


def default_controller_options(model: Any) -> Dict[str, Any]:
    """:data:`PANORAMA_CONTROLLER_OPTIONS` for a model of image observations, else none (the
    controller's defaults: the plain reach threshold)."""
    return dict(PANORAMA_CONTROLLER_OPTIONS) if _reads_images(model) else {}


#: :class:`~agents.search.planner.BufferPlanner`'s ``detour`` for agents of panoramas
PANORAMA_DETOUR = 1.5


def default_detour(model: Any) -> Optional[float]:
    """:data:`PANORAMA_DETOUR` for a model of image observations, else ``None`` (off).

    On panoramas the cost cut-off sends agents on detours longer and costlier than their plain
    routes, and admitting the plain route where it is trusted
    (:func:`~agents.search.pruning.trusted_edges`) lowers the cost at no loss (validation problems
    of the four apartments, 1200 runs: 1188 -> 1189 arrived, mean largest cost 47.51 -> 47.15).
    For vector agents it changes nothing that matters (CentralObstacle's Table I problems, 600 runs:
    mean largest cost 11.29 -> 11.33, all arrive either way), and their tables were made without it.
    """
    return PANORAMA_DETOUR if _reads_images(model) else None


class SecondOpinion:
    """A planner's ``second_opinion``: ``model``'s predicted steps from ``obs_a[i]`` to ``obs_b[i]``
    (``model.distance``, its ensemble combined by ``aggregate``): a second reading of the edges
    that nothing but the graph's own critic backs (:func:`~agents.search.pruning.trusted_edges`).
    Picklable, so a planner that holds one can go to other processes."""

    def __init__(self, model: Any, aggregate: str = "max") -> None:
        if not callable(getattr(model, "distance", None)):
            raise ValueError(f"a second opinion needs a model with a distance critic, got a {type(model).__name__}")
        self.model = model
        self.aggregate = aggregate

    def __call__(self, obs_a: np.ndarray, obs_b: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.distance(obs_a, obs_b, aggregate=self.aggregate), dtype=np.float64)


def default_second_opinion(critic: Any, driver: Any) -> Optional[SecondOpinion]:
    """The driver's distance critic as the second opinion of a graph ``critic`` built, where the
    driver is another model with one (the paper's pair: the unconstrained agent builds, the
    constrained one drives); else ``None``.

    Two critics trained apart rarely take the same two panoramas for neighbours: of 17 wormholes
    measured on Apartment2's and Apartment3's graphs (hops the unconstrained critic reads at 4-7
    steps that are 40-65 steps long), the constrained agents read 16 at 19-20 steps; the 17th,
    read at 6, has a cost reading the trust test flags on its own.
    """
    reads = all(callable(getattr(driver, f, None)) for f in ("distance", "pairwise"))
    if driver is None or driver is critic or not reads:
        return None  # no model of its own, or a policy that only drives
    return SecondOpinion(driver)


__all__ = ["DistanceFn", "PANORAMA_CONTROLLER_OPTIONS", "PANORAMA_DETOUR",
           "PANORAMA_REACH_THRESHOLD", "PolicyFn", "REACH_THRESHOLD", "SecondOpinion", "buffer_observations",
           "check_models", "default_controller_options", "default_detour", "default_hold",
           "default_reach_threshold", "default_second_opinion", "distance_fn", "env_observations", "policy_fn"]
