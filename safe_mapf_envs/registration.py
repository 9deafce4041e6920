"""One table of environment ids, registered with Gymnasium on ``import safe_mapf_envs``."""
from __future__ import annotations

import difflib
import importlib
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

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
#: ``gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` (vector ids)
_VECTOR = "safe_mapf_envs.vector:SafeNavigationVectorEnv"

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


def reachable_goal_band(spec: EnvSpec) -> Tuple[float, float]:
    """``(0, max_episode_steps * action_scale)``: goals an agent can reach within the time limit.

    The geodesic distance an agent covers moving at full speed (one ``action_scale`` per step)
    along the shortest path; the registered single-agent ids sample their default goals in it.
    """
    return 0.0, float(spec.max_episode_steps) * float(spec.kwargs.get("action_scale", 1.0))


def register_envs() -> None:
    """Register every id in :data:`ENV_SPECS` (idempotent).

    The Gymnasium registration adds ``goal_distance=``:func:`reachable_goal_band` to each id's
    keyword arguments, so default episodes are solvable; :attr:`EnvSpec.kwargs` (which the
    multi-agent factories inherit, with their 300-step episodes) do not carry it.
    """
    for spec in ENV_SPECS:
        if spec.id in gym.registry:
            continue
        gym.register(
            id=spec.id,
            entry_point=spec.entry_point,
            max_episode_steps=spec.max_episode_steps,
            kwargs={"goal_distance": reachable_goal_band(spec), **spec.kwargs},
            vector_entry_point=_VECTOR if spec.obs_type == "vector" else None,
        )


def check_env_id(env_id: Any) -> str:
    """``env_id`` if ``gymnasium.make`` knows it, else ``ValueError`` naming it and the ids of this package.

    A ``"module:Id"`` prefix is imported first, as ``gymnasium.make`` does, so ids that another
    package registers on import pass too. Commands call this before any work.
    """
    if not isinstance(env_id, str) or not env_id:
        raise ValueError(f"an env id must be a non-empty string, got {env_id!r}")
    module, _, name = env_id.rpartition(":")
    if module:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ValueError(f"env id {env_id!r}: cannot import module {module!r} ({exc})") from None
    if name not in gym.registry:
        ours = [s.id for s in ENV_SPECS]
        close = difflib.get_close_matches(name, ours, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"unknown env id {env_id!r}{hint}; this package registers: {', '.join(ours)}")
    return env_id


def env_spec(env_id: str) -> EnvSpec:
    """The :class:`EnvSpec` of a registered id, the package's own or one :func:`register_map` added
    (the ``safe_mapf_envs:`` prefix is accepted)."""
    env_id = env_id.split(":", 1)[-1]
    for spec in ENV_SPECS:
        if spec.id == env_id:
            return spec
    if env_id in _MAP_SPECS:
        return _MAP_SPECS[env_id]
    known = [s.id for s in ENV_SPECS] + list(_MAP_SPECS)
    raise KeyError(f"unknown env id {env_id!r}; registered: {', '.join(known)}")


#: the ids :func:`register_map` added in this process, by id
_MAP_SPECS: Dict[str, EnvSpec] = {}


def register_map(layout: Any, base: str = "SafeCentralObstacle-v0", env_id: Optional[str] = None) -> str:
    """Register a map of one's own as an env id, and return the id.

    The new id behaves as ``base`` does (observation type, episode length, action scale, ...) on
    ``layout``: ``gymnasium.make(id)``, ``safe_mapf_envs.parallel_env(id, n_agents=...)`` and every
    command that takes an env id accept it.

    Args:
        layout: a :class:`~safe_mapf_envs.maps.GridMap` (for example
            ``GridMap.from_movingai("room-32-32-4.map")``) or any layout object the envs accept.
        base: the registered id whose settings the new id takes.
        env_id: the id to register; default ``Safe<layout.name>-v0``, with ``Visual`` before the
            version where ``base`` observes panoramas.

    Registering the same layout under the same id again returns the id; another layout under an
    id already taken raises ``ValueError``. Ids live in the process that registered them: Ray
    workers get them from :func:`map_specs` (the evaluation does this).
    """
    base_spec = env_spec(base)
    name = getattr(layout, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError(f"a layout needs a non-empty name, got {name!r}")
    if env_id is None:
        env_id = f"Safe{name}{'Visual' if base_spec.obs_type != 'vector' else ''}-v0"
    kwargs = {**base_spec.kwargs, "layout": layout}
    spec = EnvSpec(env_id, base_spec.entry_point, name, obs_type=base_spec.obs_type,
                   max_episode_steps=base_spec.max_episode_steps, kwargs=kwargs)
    register_spec(spec)
    return env_id


def register_spec(spec: EnvSpec) -> None:
    """Register one :class:`EnvSpec` of a map of one's own with Gymnasium (what :func:`register_map`
    and Ray workers given :func:`map_specs` call); ``ValueError`` if its id names something else."""
    if any(s.id == spec.id for s in ENV_SPECS):
        raise ValueError(f"env id {spec.id!r} is one of this package's own ids; choose another name for the map")
    known = _MAP_SPECS.get(spec.id)
    if known is not None:
        if known == spec:
            return
        raise ValueError(f"env id {spec.id!r} is already registered for another map; pass env_id= to register "
                         "this one under another id")
    if spec.id in gym.registry:
        raise ValueError(f"env id {spec.id!r} is already registered by another package; pass env_id=")
    gym.register(
        id=spec.id,
        entry_point=spec.entry_point,
        max_episode_steps=spec.max_episode_steps,
        kwargs={"goal_distance": reachable_goal_band(spec), **spec.kwargs},
        vector_entry_point=_VECTOR if spec.obs_type == "vector" else None,
    )
    _MAP_SPECS[spec.id] = spec


def map_specs() -> List[EnvSpec]:
    """The specs :func:`register_map` added in this process (to register them in another with
    :func:`register_spec`)."""
    return list(_MAP_SPECS.values())


__all__ = ["ENV_SPECS", "EnvSpec", "check_env_id", "env_spec", "map_specs", "reachable_goal_band", "register_envs",
           "register_map", "register_spec"]
