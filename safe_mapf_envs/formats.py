"""Observation formats: the goal-conditioned ``Dict`` and one flat ``Box`` for tools that want one.

``observation_format="dict"`` (the default) keeps the Gymnasium-Robotics keys (``observation``,
``achieved_goal``, ``desired_goal``, and ``neighbors`` in the multi-agent env).
``observation_format="flat"`` concatenates what a policy needs into one ``Box``, for tools that
take no ``Dict`` (SuperSuit's ``black_death_v3`` and vector-env converters, SB3's ``MlpPolicy``
and ``CnnPolicy``); ``achieved_goal`` is left out, being ``observation`` itself:

- vector observations: ``float32`` ``[observation (2), desired_goal (2), neighbors (2k)]``;
- panoramas ``(V, S, S, C)``: one channel-first ``uint8`` image ``(C, 2S, V*S)``, SB3's image
  layout: the top half shows the agent's ``V`` views side by side (north, east, south, west),
  the bottom half the views from the goal, channels R, G, B, depth. SB3's ``CnnPolicy`` reads it
  as an image (its default ``NatureCNN`` needs at least 36 pixels per side, which the 64 x 128
  image of a 32-pixel panorama has and a single 32 x 32 view would not).
"""
from __future__ import annotations

from typing import Any, Dict, Mapping, cast

import numpy as np
from gymnasium import spaces

#: The values of ``observation_format``.
OBSERVATION_FORMATS = ("dict", "flat")

#: The keys of a flat vector observation, in order (``neighbors`` only where the Dict has it).
FLAT_KEYS = ("observation", "desired_goal", "neighbors")


def check_observation_format(value: Any) -> str:
    """``value`` if it is one of :data:`OBSERVATION_FORMATS`, else ``ValueError`` naming it."""
    if not isinstance(value, str) or value not in OBSERVATION_FORMATS:
        raise ValueError(f"observation_format must be one of {list(OBSERVATION_FORMATS)}, got {value!r}")
    return value


def _is_panorama(space: spaces.Box) -> bool:
    return space.dtype == np.uint8 and len(space.shape) == 4


def flat_space(space: spaces.Dict) -> spaces.Box:
    """The ``Box`` of :func:`flatten_observation` for a goal-conditioned ``Dict`` space."""
    obs = cast(spaces.Box, space["observation"])
    if _is_panorama(obs):
        v, s, s2, c = obs.shape
        return spaces.Box(0, 255, shape=(c, s + s2, v * s), dtype=np.uint8)
    parts = [cast(spaces.Box, space[k]) for k in FLAT_KEYS if k in space.spaces]
    low = np.concatenate([p.low.ravel() for p in parts]).astype(np.float32)
    high = np.concatenate([p.high.ravel() for p in parts]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def flatten_observation(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    """One flat observation from a goal-conditioned dict; leading batch dimensions are kept.

    Vectors: ``observation``, ``desired_goal`` and (if present) ``neighbors`` concatenated along
    the last axis. Panoramas ``(..., V, S, S, C)``: the channel-first image ``(..., C, 2S, V*S)``
    described in the module docstring.
    """
    o, g = np.asarray(obs["observation"]), np.asarray(obs["desired_goal"])
    if o.dtype == np.uint8 and o.ndim >= 4:
        v, s, _, c = o.shape[-4:]
        lead = o.shape[:-4]
        both = np.stack([o, g], axis=-5)  # (..., 2, V, S, S, C): half, view, row, column, channel
        nd = both.ndim
        order = (*range(nd - 5), nd - 1, nd - 5, nd - 3, nd - 4, nd - 2)  # channel, half, row, view, column
        return np.ascontiguousarray(both.transpose(order)).reshape(*lead, c, 2 * s, v * s)
    lead = o.shape[:-1]
    parts = [o, g]
    if "neighbors" in obs:
        nb = np.asarray(obs["neighbors"])
        parts.append(nb.reshape(*lead, -1))
    return np.concatenate(parts, axis=-1).astype(np.float32, copy=False)


def flatten_agents(observations: Dict[str, Dict[str, np.ndarray]]) -> Dict[str, np.ndarray]:
    """:func:`flatten_observation` for every agent of a PettingZoo observation dict, in one batch."""
    if not observations:
        return {}
    names = list(observations)
    first = observations[names[0]]
    batch = {k: np.stack([observations[a][k] for a in names]) for k in first}
    flat = flatten_observation(batch)
    return dict(zip(names, flat))


__all__ = [
    "FLAT_KEYS", "OBSERVATION_FORMATS", "check_observation_format", "flat_space", "flatten_agents",
    "flatten_observation",
]
