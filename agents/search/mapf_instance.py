"""Old import path of the MAPF instance, kept for one release: use
:mod:`agents.search.mapf.instance`, which this module re-exports.
"""
from .mapf.instance import (  # noqa: F401
    TIME_MODELS,
    UNREACHABLE,
    GraphLike,
    MapfInstance,
    Proximity,
    as_proximity,
    edges_from_graph,
    integer_durations,
)

#: the old name of :func:`agents.search.mapf.instance.edges_from_graph`
_edges_from_graph = edges_from_graph
