"""What a CBS solve returns: :class:`CBSResult` (status, paths, costs, bounds) and :class:`CBSStats`."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional, Tuple

#: Possible values of :attr:`CBSResult.status`.
STATUSES = ("optimal", "suboptimal", "timeout", "infeasible")


@dataclass
class CBSStats:
    """Search statistics of one solve."""

    hl_expanded: int = 0
    hl_generated: int = 0
    ll_expanded: int = 0
    ll_calls: int = 0
    runtime_s: float = 0.0
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
class CBSResult:
    """The outcome of a CBS solve.

    Attributes:
        status: ``"optimal"``, ``"suboptimal"`` (ECBS; cost within ``suboptimality`` x optimum),
            ``"timeout"`` (time, memory or node limit reached first) or ``"infeasible"`` (proved).
        paths: per agent, the timed path ``[(node, time), ...]``: the agent is at ``node`` at
            ``time``; one entry per time step under unit time; arrivals and each waiting step
            under the durative model (between two entries ``(u, t), (v, t + d)`` with ``u != v``
            the agent traverses the edge). The last entry is the final arrival at the goal, where
            the agent then stays. ``None`` unless solved.
        soc: sum over agents of the final arrival times.
        makespan: the latest final arrival time.
        lower_bound: a proven lower bound on the optimal sum of costs (``None`` if unknown).
        stats: search statistics.
        message: why the search ended the way it did, in words.
        time_model: ``"unit"`` or ``"durative"``.
    """

    status: str
    paths: Optional[List[List[Tuple[int, int]]]] = None
    soc: Optional[int] = None
    makespan: Optional[int] = None
    lower_bound: Optional[int] = None
    stats: CBSStats = field(default_factory=CBSStats)
    message: str = ""
    time_model: str = "unit"

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
        """A JSON-friendly summary (paths included)."""
        d: Dict[str, Any] = {
            "status": self.status,
            "soc": self.soc,
            "makespan": self.makespan,
            "lower_bound": self.lower_bound,
            "message": self.message,
            "time_model": self.time_model,
        }
        d.update(asdict(self.stats))
        d["paths"] = None if self.paths is None else [[list(e) for e in p] for p in self.paths]
        return d
