"""Old import path of the CBS solver, kept for one release: use :mod:`agents.search.mapf`.

The solver moved to the :mod:`agents.search.mapf` package (one concept per module); this module
re-exports the names it used to define or import.
"""
from .mapf.cbs import CBSSearch
from .mapf.conflicts import CARDINAL, EDGE, NON_CARDINAL, SEMI_CARDINAL, TARGET, VERTEX, Conflict  # noqa: F401
from .mapf.constraints import (  # noqa: F401
    EMPTY,
    FOREVER,
    ConstraintSet,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
from .mapf.context import SearchContext, _rss_bytes  # noqa: F401
from .mapf.ctnode import CTNode
from .mapf.ecbs import ECBSSearch
from .mapf.heuristics import min_vertex_cover, mvc_components
from .mapf.instance import MapfInstance, Proximity, integer_durations
from .mapf.lowlevel import Counter, SearchTimeout, earliest_arrival, focal_search, space_time_astar  # noqa: F401
from .mapf.mdd import MDD, build_mdd, mdds_dependent, prune_mdd  # noqa: F401
from .mapf.paths import AgentPath, Reservation, satisfies  # noqa: F401
from .mapf.result import STATUSES, CBSResult, CBSStats
from .mapf.solver import DEFAULT_MEMORY_LIMIT_MB, HEURISTICS, CBSSolver, _pair_feasible, solve_cbs  # noqa: F401
from .mapf.symmetry import Corridors, GridGeometry  # noqa: F401

__all__ = [
    "CBSResult",
    "CBSSolver",
    "CBSStats",
    "CTNode",
    "MapfInstance",
    "Proximity",
    "STATUSES",
    "integer_durations",
    "solve_cbs",
]

# the old names of internals that now have public names in the package
_Context = SearchContext
_CBS = CBSSearch
_ECBS = ECBSSearch
_min_vertex_cover = min_vertex_cover
_mvc_components = mvc_components
