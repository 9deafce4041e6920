"""The Apartment1 apartment with N agents: ``parallel_env``, ``raw_env`` and ``env`` (AEC) factories.

Panorama observations in a furnished apartment, in metres, as ``SafeApartment1-v0``.
``parallel_env(n_agents=4, render_mode=None, **kwargs)`` is
``safe_mapf_envs.parallel_env("SafeApartment1-v0", n_agents, ...)``; see
:class:`safe_mapf_envs.multi_agent.SafeMultiNavigationEnv` for the arguments.
"""
from ..factories import map_factories

ENV_ID = "SafeApartment1-v0"

parallel_env, raw_env, env = map_factories(ENV_ID, __name__)

__all__ = ["ENV_ID", "env", "parallel_env", "raw_env"]
