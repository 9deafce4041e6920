"""Adapters from trained models to the search: policy and distance functions, graph nodes, defaults.

The functions here turn a goal-conditioned SB3 model into what the planner and the controller
call (``policy(obs, goals)``, ``distance(obs, goals)``), draw graph nodes from a replay buffer or
an env, and check that a critic and a driver belong together. The settings that suit a model's
observations (vectors or panoramas) are :func:`agents.search.config.preset_for`'s. This module does
not import torch.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping, Optional

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


class SecondOpinion:
    """A planner's ``second_opinion``: ``model``'s predicted steps from ``obs_a[i]`` to ``obs_b[i]``
    (``model.distance``, its ensemble combined by ``aggregate``): a second reading of the edges
    that nothing but the graph's own critic backs (:func:`~agents.search.graph.pruning.trusted_edges`).
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


__all__ = ["DistanceFn", "PolicyFn", "SecondOpinion", "buffer_observations", "check_models", "default_second_opinion",
           "distance_fn", "env_observations", "policy_fn"]
