"""The waypoint graph: building it from critic matrices, pruning it, attaching a problem's
endpoints (:mod:`~agents.search.graph.build`, :mod:`~agents.search.graph.pruning`), merging
look-alike nodes (:mod:`~agents.search.graph.sparsify`) and single-agent search on it
(:mod:`~agents.search.graph.single`)."""
from .build import NodePairwise, ProblemGraph, WaypointGraph, build_problem_graph
from .single import Plan, risk_bounded_path, shortest_path

__all__ = ["NodePairwise", "Plan", "ProblemGraph", "WaypointGraph", "build_problem_graph", "risk_bounded_path",
           "shortest_path"]
