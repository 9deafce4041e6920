"""Safe single- and multi-agent navigation environments.

Importing the package registers the Gymnasium ids listed in
:data:`safe_mapf_envs.registration.ENV_SPECS`, e.g.::

    import gymnasium as gym
    import safe_mapf_envs  # noqa: F401  (or use the id "safe_mapf_envs:SafeCentralObstacle-v0")

    env = gym.make("SafeCentralObstacle-v0", render_mode="rgb_array")
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    info["cost"]  # the safety cost of this step

    # visual navigation: RGB-D panoramas (4 views x 32 x 32 x RGB+depth) in furnished apartments
    vis = gym.make("SafeApartment0-v0")

    # N agents on the same map (PettingZoo; ``env``/``raw_env`` give the AEC form)
    par = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=10)

    # one Box per observation (observation and goal concatenated), for SuperSuit and MlpPolicy
    flat = gym.make("SafeCentralObstacle-v0", observation_format="flat")

    # 64 episodes stepped in one batch (the same episodes as vectorization_mode="sync")
    vec = gym.make_vec("SafeCentralObstacle-v0", num_envs=64, vectorization_mode="vector_entry_point")

    # a map of one's own (MovingAI .map, occupancy image or .npy array) under an id of its own
    room = safe_mapf_envs.GridMap.from_file("room-32-32-4.map")
    env_id = safe_mapf_envs.register_map(room)  # "SafeRoom-32-32-4-v0"

This package imports no torch and nothing from ``agents`` or ``baselines``.
"""
from importlib import metadata as _metadata

from .base import NavigationEnvBase
from .cost import COST_FUNCTIONS, ObstacleField
from .factories import env, parallel_env, raw_env
from .formats import OBSERVATION_FORMATS, flat_space, flatten_observation
from .maps import APARTMENTS, MAPS, Apartment, GridMap, get_map
from .multi_agent import SafeMultiNavigationEnv
from .registration import ENV_SPECS, EnvSpec, env_spec, map_specs, register_envs, register_map
from .scenario import NavigationScenario
from .sensors import PanoramaSensor, Scene, render_panoramas, scene_for_layout
from .single_agent import SafeNavigationEnv
from .vector import SafeNavigationVectorEnv
from .wrappers import SafetyGymnasiumStyle

try:
    #: The installed distribution's version (``safe-mapf``), shared by ``agents`` and ``baselines``.
    __version__ = _metadata.version("safe-mapf")
except _metadata.PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"

register_envs()

from . import multi  # noqa: E402  (per-map PettingZoo modules; needs the id table above)

__all__ = [
    "APARTMENTS",
    "Apartment",
    "COST_FUNCTIONS",
    "ENV_SPECS",
    "EnvSpec",
    "GridMap",
    "MAPS",
    "OBSERVATION_FORMATS",
    "NavigationEnvBase",
    "NavigationScenario",
    "ObstacleField",
    "PanoramaSensor",
    "SafeMultiNavigationEnv",
    "SafeNavigationEnv",
    "SafeNavigationVectorEnv",
    "SafetyGymnasiumStyle",
    "__version__",
    "Scene",
    "env_spec",
    "env",
    "flat_space",
    "flatten_observation",
    "get_map",
    "map_specs",
    "multi",
    "parallel_env",
    "raw_env",
    "register_envs",
    "register_map",
    "render_panoramas",
    "scene_for_layout",
]
