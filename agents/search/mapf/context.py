"""What every search of one CBS solve shares: the instance, the limits, the caches and the counters.

A :class:`SearchContext` lives for one :meth:`~agents.search.mapf.solver.CBSSolver.solve`; the
main search, the pair sub-searches of the WDG heuristic and ECBS all read and fill it.
:meth:`SearchContext.check_time` enforces the deadline and the memory guard.
"""
from __future__ import annotations

import itertools
import os
import sys
import time as _time
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Tuple

from .constraints import CompiledConstraints, ConstraintSet, compile_constraints
from .instance import MapfInstance
from .lowlevel import Counter, SearchTimeout
from .mdd import MDD
from .paths import AgentPath
from .result import CBSStats
from .symmetry import Corridors, GridGeometry

if TYPE_CHECKING:  # the solver builds the context; imported for the annotation only
    from .solver import CBSSolver

#: the deferred pair feasibility check runs once a search has made this many low-level expansions
#: (about a second of search) without a plan
PAIR_CHECK_AFTER_EXPANSIONS = 5_000
#: the work budget of the deferred pair feasibility check: joint moves examined over all pairs
PAIR_CHECK_MOVES = 20_000_000

#: the memory guard reads the process's resident size once every this many checks
_MEMORY_CHECK_EVERY = 256

#: ``(agent, constraint content)``: what results that depend on one agent's constraints are keyed by
AgentKey = Tuple[int, frozenset]
#: ``(agent i, agent j, content of i, content of j)``: the key of results on a pair of agents
PairKey = Tuple[int, int, frozenset, frozenset]


def _rss_bytes() -> Optional[int]:
    """The resident memory of this process in bytes, or ``None`` where it cannot be read.

    Linux: the current resident size (``/proc/self/statm``). Elsewhere with :mod:`resource`:
    the peak resident size, which only grows (still a valid guard). Otherwise ``None``.
    """
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024


class SearchContext:
    """What every search of one solve shares: the instance, limits, caches and counters."""

    def __init__(self, inst: MapfInstance, deadline: float, options: CBSSolver):
        self.inst = inst
        self.deadline = deadline
        self.opt = options
        #: resident-memory ceiling in bytes (the process's size at the start plus the limit)
        self.memory_cap: Optional[int] = None
        if options.memory_limit_mb is not None:
            base = _rss_bytes()
            if base is not None:
                self.memory_cap = base + int(options.memory_limit_mb * (1 << 20))
        self._checks = 0
        #: ``"time"``, ``"work"`` or ``"memory"``: which limit ended the search
        self.stop_reason = "time"
        self.counter = Counter()
        #: (agent, constraint content) -> its MDD
        self.mdds: Dict[AgentKey, MDD] = {}
        #: (agent i, agent j, content of i, content of j) -> optimal cost of the pair alone
        self.pairs: Dict[PairKey, int] = {}
        #: pair key -> (optimal cost, the two paths) of solved pair sub-problems (unit time)
        self.pair_solutions: Dict[PairKey, Tuple[int, AgentPath, AgentPath]] = {}
        #: per agent pair, how many of its pair searches stopped at their node limit
        self.pair_limit_hits: Dict[Tuple[int, int], int] = {}
        #: pair key -> whether no two cheapest paths of the pair avoid each other
        self.dependent: Dict[PairKey, bool] = {}
        #: (agent, constraint content, target, corridor or None) -> earliest arrival
        self.arrivals: Dict[Tuple[int, frozenset, int, Optional[int]], int] = {}
        #: (agent, constraint content) -> the compiled constraints
        self.compiled: Dict[AgentKey, CompiledConstraints] = {}
        #: (meta-agent's global ids, its members' constraint contents) -> its joint plan, ``None``
        #: (no plan) or the :class:`~agents.search.mapf.coupled.CoupledLimit` its search stopped at
        self.coupled: Dict[Tuple[Tuple[int, ...], Tuple[frozenset, ...]], Any] = {}
        #: group bounds: (sorted global ids, their constraint contents) -> (a lower bound on the
        #: group's optimal joint cost alone, its joint paths when that is the optimum, else None)
        self.group_costs: Dict[Tuple[Tuple[int, ...], Tuple[frozenset, ...]],
                               Tuple[int, Optional[Tuple[AgentPath, ...]]]] = {}
        #: group bounds: per group (sorted global ids), [times evaluated, times it added a constraint]
        self.group_use: Dict[Tuple[int, ...], List[int]] = {}
        #: group bounds: expansions of their coupled searches so far
        self.group_expanded = 0
        self.stats = CBSStats()
        self.ids = itertools.count()
        self._corridors: Optional[Corridors] = None
        self.geometry: Optional[GridGeometry] = None
        size = options._pair_check_size()
        #: after how many low-level expansions to run the deferred pair feasibility check (None: never)
        self.pair_check_at: Optional[int] = (
            PAIR_CHECK_AFTER_EXPANSIONS if options.pair_check_states < size <= 100 * options.pair_check_states
            else None)
        self.infeasible_reason: Optional[str] = None
        if options.symmetry and inst.unit and options.grid_coords is not None:
            self.geometry = GridGeometry(inst, options.grid_coords)

    def corridors(self) -> Optional[Corridors]:
        """The corridor index (built on first use; unit time only)."""
        if self._corridors is None and self.opt.symmetry and self.inst.unit:
            self._corridors = Corridors(self.inst)
        return self._corridors

    def compile(self, gid: int, cons: ConstraintSet) -> CompiledConstraints:
        """Agent ``gid``'s constraints compiled for the low level (cached by content)."""
        key = (gid, cons.content)
        cc = self.compiled.get(key)
        if cc is None:
            cc = compile_constraints(cons, self.inst.n_nodes, self.inst.goals[gid])
            if len(self.compiled) > 200_000:
                self.compiled.clear()
            self.compiled[key] = cc
        return cc

    def check_time(self) -> None:
        """Raise :class:`SearchTimeout` past the deadline, the expansion limit or (checked now and
        then) the memory cap."""
        if _time.perf_counter() > self.deadline:
            raise SearchTimeout
        limit = self.opt.expansion_limit
        if limit is not None and self.counter.expanded > limit:
            self.stop_reason = "work"
            raise SearchTimeout
        if self.memory_cap is not None:
            self._checks += 1
            if self._checks % _MEMORY_CHECK_EVERY == 1:
                rss = _rss_bytes()
                if rss is not None and rss > self.memory_cap:
                    self.stop_reason = "memory"
                    raise SearchTimeout
