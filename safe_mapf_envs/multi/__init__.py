"""One module per map with PettingZoo factories, in PettingZoo's layout::

    from safe_mapf_envs.multi import central_obstacle_v0

    env = central_obstacle_v0.parallel_env(n_agents=10)   # ParallelEnv
    aec = central_obstacle_v0.env(n_agents=10)            # AEC form, wrapped

There is one module for each grid map (``central_obstacle_v0``, ``center_dot_v0``,
``four_rooms_v0``, ``spiral_v0``, ``maze_v0``, ``u_v0``, ``tunnel_v0``) and for each apartment
(``apartment0_v0`` .. ``apartment3_v0``, panorama observations). ``SafeCentralObstacleVisual-v0``
(the CentralObstacle map seen in panoramas) has none: it is
``safe_mapf_envs.parallel_env("SafeCentralObstacleVisual-v0", n_agents)``, and so is any
registered id. :data:`MODULES` maps each registered single-agent id to its module.
"""
from . import (
    apartment0_v0,
    apartment1_v0,
    apartment2_v0,
    apartment3_v0,
    center_dot_v0,
    central_obstacle_v0,
    four_rooms_v0,
    maze_v0,
    spiral_v0,
    tunnel_v0,
    u_v0,
)

#: Registered single-agent id -> per-map multi-agent module.
MODULES = {
    m.ENV_ID: m
    for m in (central_obstacle_v0, center_dot_v0, four_rooms_v0, spiral_v0, maze_v0, u_v0, tunnel_v0,
              apartment0_v0, apartment1_v0, apartment2_v0, apartment3_v0)
}

__all__ = [
    "MODULES",
    "apartment0_v0",
    "apartment1_v0",
    "apartment2_v0",
    "apartment3_v0",
    "center_dot_v0",
    "central_obstacle_v0",
    "four_rooms_v0",
    "maze_v0",
    "spiral_v0",
    "tunnel_v0",
    "u_v0",
]
