"""One table of environment ids, registered with Gymnasium on ``import safe_mapf_envs``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List

import gymnasium as gym

from .maps.apartments import APARTMENT_ENV_KWARGS


@dataclass(frozen=True)
class EnvSpec:
    """One registered environment: its id, entry point, map and keyword arguments."""

    id: str
    entry_point: str
    layout: str
    obs_type: str = "vector"
    max_episode_steps: int = 20
    kwargs: Dict[str, Any] = field(default_factory=dict)


_SINGLE = "safe_mapf_envs.single_agent:SafeNavigationEnv"

#: Every registered id. Training ids use 20 steps per episode, as in the paper.
ENV_SPECS: List[EnvSpec] = [
    EnvSpec(f"Safe{name}-v0", _SINGLE, name, kwargs={"layout": name})
    for name in ("CentralObstacle", "CenterDot", "FourRooms", "Spiral", "Maze", "U", "Tunnel")
]
# Visual navigation: furnished apartments in metres seen through RGB-D panoramas, and the 2D
# benchmark map seen the same way.
ENV_SPECS += [
    EnvSpec(f"Safe{name}-v0", _SINGLE, name, obs_type="panorama",
            kwargs={"layout": name, "obs_type": "panorama", **APARTMENT_ENV_KWARGS})
    for name in ("Apartment0", "Apartment1", "Apartment2", "Apartment3")
]
ENV_SPECS.append(EnvSpec("SafeCentralObstacleVisual-v0", _SINGLE, "CentralObstacle", obs_type="panorama",
                         kwargs={"layout": "CentralObstacle", "obs_type": "panorama"}))


def register_envs() -> None:
    """Register every id in :data:`ENV_SPECS` (idempotent)."""
    for spec in ENV_SPECS:
        if spec.id in gym.registry:
            continue
        gym.register(
            id=spec.id,
            entry_point=spec.entry_point,
            max_episode_steps=spec.max_episode_steps,
            kwargs=dict(spec.kwargs),
        )


def env_spec(env_id: str) -> EnvSpec:
    """The :class:`EnvSpec` of a registered id (the ``safe_mapf_envs:`` prefix is accepted)."""
    env_id = env_id.split(":", 1)[-1]
    for spec in ENV_SPECS:
        if spec.id == env_id:
            return spec
    raise KeyError(f"unknown env id {env_id!r}; registered: {', '.join(s.id for s in ENV_SPECS)}")


__all__ = ["ENV_SPECS", "EnvSpec", "env_spec", "register_envs"]
