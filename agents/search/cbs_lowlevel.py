"""Old import path of the CBS low level, kept for one release: use :mod:`agents.search.mapf`.

Its contents moved to :mod:`agents.search.mapf.paths` (timed paths, reservations),
:mod:`agents.search.mapf.conflicts` (conflict detection), :mod:`agents.search.mapf.lowlevel`
(the searches), :mod:`agents.search.mapf.successors` (what they share) and
:mod:`agents.search.mapf.mdd`; this module re-exports the names it used to define.
"""
from .mapf.conflicts import pair_conflicts  # noqa: F401
from .mapf.lowlevel import Counter, SearchTimeout, earliest_arrival, focal_search, space_time_astar  # noqa: F401
from .mapf.mdd import MDD, build_mdd, mdds_dependent, prune_mdd  # noqa: F401
from .mapf.paths import AgentPath, Reservation, satisfies  # noqa: F401
from .mapf.successors import Expander, make_expander  # noqa: F401
