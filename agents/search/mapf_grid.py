"""Old import path of the MovingAI benchmark loaders, kept for one release: use
:mod:`agents.search.mapf.movingai`, which this module re-exports.
"""
from .mapf.movingai import (  # noqa: F401
    FREE_CHARS,
    Cell,
    GridInstance,
    GridMap,
    PathLike,
    ScenAgent,
    grid_graph,
    load_instance,
    load_map,
    load_scen,
)
