"""PettingZoo entry points of the multi-agent environment: :func:`parallel_env` (the native
parallel env), :func:`raw_env` and :func:`env` (its AEC form, derived with PettingZoo's
``parallel_to_aec``), and :func:`map_factories` for the per-map modules of
:mod:`safe_mapf_envs.multi`.
"""
from __future__ import annotations

from typing import Callable, Tuple

from pettingzoo import AECEnv
from pettingzoo.utils import wrappers
from pettingzoo.utils.conversions import parallel_to_aec

from .multi_agent import SafeMultiNavigationEnv
from .registration import env_spec


def parallel_env(env_id: str = "SafeCentralObstacle-v0", n_agents: int = 4, **kwargs) -> SafeMultiNavigationEnv:
    """The multi-agent env on the map of a registered single-agent id.

    Args:
        env_id: a registered id such as ``"SafeCentralObstacle-v0"`` (the
            ``"safe_mapf_envs:"`` prefix is accepted); its map, observation type and keyword
            arguments are inherited.
        n_agents: number of agents.
        **kwargs: :class:`SafeMultiNavigationEnv` arguments (``render_mode``, ``max_cycles``,
            ...); they override the id's.
    """
    try:
        spec = env_spec(env_id)
    except KeyError as exc:
        raise ValueError(exc.args[0]) from None
    merged = {**spec.kwargs, **kwargs}
    merged.setdefault("layout", spec.layout)
    if spec.obs_type != "vector":
        merged.setdefault("obs_type", spec.obs_type)
    return SafeMultiNavigationEnv(n_agents=n_agents, **merged)


def raw_env(env_id: str = "SafeCentralObstacle-v0", n_agents: int = 4, **kwargs) -> AECEnv:
    """The AEC form of :func:`parallel_env`, without wrappers."""
    return parallel_to_aec(parallel_env(env_id, n_agents=n_agents, **kwargs))


def env(env_id: str = "SafeCentralObstacle-v0", n_agents: int = 4, **kwargs) -> AECEnv:
    """The AEC form of :func:`parallel_env` with PettingZoo's order-enforcing wrapper."""
    return wrappers.OrderEnforcingWrapper(raw_env(env_id, n_agents=n_agents, **kwargs))


def map_factories(
    env_id: str, module: str
) -> Tuple[Callable[..., SafeMultiNavigationEnv], Callable[..., AECEnv], Callable[..., AECEnv]]:
    """``(parallel_env, raw_env, env)`` bound to one registered id, for a per-map module.

    The functions take ``n_agents=4`` and the keyword arguments of
    :class:`SafeMultiNavigationEnv`; they are named after ``module`` so they pickle.
    """
    spec = env_spec(env_id)

    def _parallel_env(n_agents: int = 4, **kwargs) -> SafeMultiNavigationEnv:
        return parallel_env(spec.id, n_agents=n_agents, **kwargs)

    def _raw_env(n_agents: int = 4, **kwargs) -> AECEnv:
        return raw_env(spec.id, n_agents=n_agents, **kwargs)

    def _env(n_agents: int = 4, **kwargs) -> AECEnv:
        return env(spec.id, n_agents=n_agents, **kwargs)

    docs = {
        "parallel_env": f"The {spec.layout} map with ``n_agents`` agents (PettingZoo parallel API).",
        "raw_env": f"The {spec.layout} map with ``n_agents`` agents, AEC form without wrappers.",
        "env": f"The {spec.layout} map with ``n_agents`` agents, AEC form with the order-enforcing wrapper.",
    }
    out = []
    for name, fn in (("parallel_env", _parallel_env), ("raw_env", _raw_env), ("env", _env)):
        fn.__name__ = fn.__qualname__ = name
        fn.__module__ = module
        fn.__doc__ = docs[name] + " Keyword arguments as for :class:`SafeMultiNavigationEnv`."
        out.append(fn)
    return tuple(out)  # type: ignore[return-value]


__all__ = ["env", "map_factories", "parallel_env", "raw_env"]
