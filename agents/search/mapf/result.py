"""What a MAPF solve returns: :class:`MapfResult`, the one result type of every solver, and
:class:`CBSStats`, the statistics of a CBS / ECBS search.

Every solver fills the fields of :class:`MapfResult` (status, paths, costs, a lower bound where it
has one, the work counted against its budget, the seconds it ran, its name); what only one solver
counts goes into :attr:`MapfResult.stats`, a statistics object of that solver's own type
(:class:`CBSStats` for CBS and ECBS).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, is_dataclass
from typing import Any, Dict, List, Optional, Tuple

#: Possible values of :attr:`MapfResult.status`.
STATUSES = ("optimal", "suboptimal", "timeout", "infeasible")


@dataclass
class CBSStats:
    """Search statistics of one CBS / ECBS solve (its work and seconds are :class:`MapfResult`'s)."""

    hl_expanded: int = 0
    hl_generated: int = 0
    #: low-level searches run
    ll_calls: int = 0
    mdds: int = 0
    pair_searches: int = 0
    pair_reuses: int = 0
    bypasses: int = 0
    #: meta-agent merges (coupled searches run to merge two (meta-)agents in a node)
    merges: int = 0
    #: meta-agents split up again in a child whose coupled search passed ``merge_node_limit``
    unmerges: int = 0
    #: splits of the main search on corridor conflicts (chains of two-neighbour nodes)
    corridor_splits: int = 0
    #: splits of the main search on pseudo-corridor conflicts (head-on, forced, anywhere)
    pseudo_corridor_splits: int = 0
    #: splits of the main search on rectangle conflicts
    rectangle_splits: int = 0
    #: group bounds (``group_bounds``): coupled searches run for a group's joint cost
    group_searches: int = 0
    #: group bounds: a group's joint cost known from an ancestor's joint plan, no search
    group_reuses: int = 0
    #: group bounds: group constraints added to a node's weighted conflict graph (a group's extra
    #: cost above the pair bounds inside it)
    group_constraints: int = 0
    #: group bounds: nodes whose heuristic the group constraints raised above the pair cover
    group_raised: int = 0


@dataclass
class MapfResult:
    """The outcome of one solve, whichever solver made it.

    Attributes:
        status: ``"optimal"`` (cost proven optimal), ``"suboptimal"`` (a plan, its cost not proven
            optimal; ECBS: within ``suboptimality`` x optimum), ``"timeout"`` (a budget, the time or
            the memory limit reached first, or an incomplete solver gave up) or ``"infeasible"`` (proved).
        paths: per agent, the timed path ``[(node, time), ...]``: the agent is at ``node`` at
            ``time``; one entry per time step under unit time; arrivals and each waiting step
            under the durative model (between two entries ``(u, t), (v, t + d)`` with ``u != v``
            the agent traverses the edge). The last entry is the final arrival at the goal, where
            the agent then stays. ``None`` unless solved.
        soc: sum over agents of the final arrival times (``None`` unless solved).
        makespan: the latest final arrival time (``None`` unless solved).
        lower_bound: a proven lower bound on the optimal sum of costs: the search's bound (CBS, ECBS),
            the sum of the agents' own distances (the other solvers), ``None`` where none is known.
        message: why the solve ended the way it did, in words.
        time_model: ``"unit"`` or ``"durative"``.
        solver: the name of the solver that made this result (the names of
            :data:`agents.search.mapf.registry.SOLVERS`, or ``"single"`` for a lone agent's shortest path).
        work: the work the solver counted against its budget, in its own unit (CBS / ECBS: low-level
            expansions; prioritised planning and the repair: search expansions; the stepper: candidate
            moves; the configuration search: its work units; 0 where nothing is counted).
        runtime_s: wall-clock seconds of the solve.
        stats: the solver's own statistics (:class:`CBSStats` for CBS / ECBS; see each solver), or
            ``None``.
    """

    status: str
    paths: Optional[List[List[Tuple[int, int]]]] = None
    soc: Optional[int] = None
    makespan: Optional[int] = None
    lower_bound: Optional[int] = None
    message: str = ""
    time_model: str = "unit"
    solver: str = ""
    work: int = 0
    runtime_s: float = 0.0
    stats: Optional[Any] = None

    @property
    def solved(self) -> bool:
        """Whether paths were found."""
        return self.paths is not None

    def node_sequences(self, pad: bool = False) -> List[List[int]]:
        """Per agent, the node at every time step ``0..arrival`` (``0..makespan`` if ``pad``).

        Under the durative model a step spent traversing an edge reports the node the agent
        left (its most recent node).
        """
        if self.paths is None:
            raise ValueError(f"no paths: the search ended with status {self.status!r}")
        out = []
        horizon = self.makespan or 0
        for events in self.paths:
            seq: List[int] = []
            for (u, t0), (_, t1) in zip(events, events[1:]):
                seq.extend([u] * (t1 - t0))
            seq.append(events[-1][0])
            if pad:
                seq.extend([seq[-1]] * (horizon + 1 - len(seq)))
            out.append(seq)
        return out

    def departures(self, agent: int) -> List[Tuple[int, int]]:
        """Waypoints of one agent as ``(node, departure time)``; the goal's time is its arrival.

        Consecutive waits collapse into one waypoint, which is what a waypoint-following
        controller needs ("do not leave node ``k`` before time ``t_k``").
        """
        if self.paths is None:
            raise ValueError(f"no paths: the search ended with status {self.status!r}")
        events = self.paths[agent]
        out: List[Tuple[int, int]] = []
        for i, (v, t) in enumerate(events):
            if i + 1 < len(events) and events[i + 1][0] == v:
                continue  # still waiting here
            out.append((v, t))
        return out

    def to_dict(self) -> dict:
        """A JSON-friendly summary (paths included; the solver's own statistics under ``"stats"``)."""
        d: Dict[str, Any] = {
            "status": self.status,
            "soc": self.soc,
            "makespan": self.makespan,
            "lower_bound": self.lower_bound,
            "message": self.message,
            "time_model": self.time_model,
            "solver": self.solver,
            "work": self.work,
            "runtime_s": self.runtime_s,
            "stats": asdict(self.stats) if is_dataclass(self.stats) and not isinstance(self.stats, type) else None,
        }
        d["paths"] = None if self.paths is None else [[list(e) for e in p] for p in self.paths]
        return d


#: The former name of :class:`MapfResult` (when only CBS returned it), kept for imports.
CBSResult = MapfResult
