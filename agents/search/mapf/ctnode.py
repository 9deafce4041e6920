"""The node of the constraint tree (CT) that the high level of CBS searches."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

from .conflicts import Conflict
from .constraints import Constraint, ConstraintSet
from .paths import AgentPath

#: Conflicts of a node by local agent pair ``(i, j)``, ``i < j``.
ConflictMap = Dict[Tuple[int, int], List[Conflict]]
#: ``{"total": cover value, "where": {agent: (component edges, component value, vertex count)},
#: (agent, cost increase): child bound, ...}`` (see the heuristics)
CoverMemo = Dict[Any, Any]


class CTNode:
    """A node of the constraint tree.

    Ordered by ``(f, n_conflicts, id)``: the lowest cost bound first, then the fewest conflicts,
    then creation order, so the search is deterministic.
    """

    __slots__ = ("g", "h", "f", "id", "depth", "paths", "cons", "conflicts", "n_conflicts", "h_done",
                 "lb", "closed", "pending", "hedges", "hmemo", "groups")

    def __init__(self, g: int, paths: List[AgentPath], cons: List[ConstraintSet],
                 conflicts: ConflictMap, node_id: int, depth: int = 0, h: int = 0):
        self.g = g
        self.h = h
        self.f = g + h
        self.id = node_id
        self.depth = depth
        self.paths = paths
        self.cons = cons
        self.conflicts = conflicts
        self.n_conflicts = sum(len(v) for v in conflicts.values())
        self.h_done = False
        self.lb = g
        self.closed = False
        #: ``(parent, {local agent: new constraint set})`` while the node is not generated yet:
        #: its paths are planned when it is first popped (``g`` and ``f`` are lower bounds until
        #: then; ``paths`` and ``cons`` are empty)
        self.pending: Optional[Tuple[CTNode, Dict[int, Tuple[ConstraintSet, Tuple[Constraint, ...]]]]] = None
        #: the weighted conflict graph ``{(i, j): weight}`` the heuristic was computed from (with
        #: group bounds also group constraints ``{(i, j, k, ...): extra cost}``)
        self.hedges: Optional[Dict[Tuple[int, ...], int]] = None
        #: the cover of ``hedges`` per component and the child bounds computed from it (see
        #: :meth:`agents.search.mapf.heuristics.ConflictGraphHeuristics._cover_memo`)
        self.hmemo: Optional[CoverMemo] = None
        #: meta-agents (MA-CBS): per local agent, the sorted local agents of its group, planned
        #: together by the coupled search; ``None`` while every agent is alone (children share
        #: their parent's tuple)
        self.groups: Optional[Tuple[Tuple[int, ...], ...]] = None

    def set_conflicts(self, conflicts: ConflictMap) -> None:
        """Replace the node's conflicts (and their count)."""
        self.conflicts = conflicts
        self.n_conflicts = sum(len(v) for v in conflicts.values())

    def __lt__(self, other: CTNode) -> bool:
        if self.f != other.f:
            return self.f < other.f
        if self.n_conflicts != other.n_conflicts:
            return self.n_conflicts < other.n_conflicts
        return self.id < other.id

    def __repr__(self) -> str:
        return f"CTNode(id={self.id}, g={self.g}, h={self.h}, f={self.f}, conflicts={self.n_conflicts})"
