"""Conflicts between two agents' timed paths: kinds, classes, and their detection.

A :class:`Conflict` names two agents, a time step and the nodes involved; its
:meth:`~Conflict.branches` are the two constraint sets that resolve it (every conflict-free
solution meets one of them). :func:`pair_conflicts` lists the conflicts between two
:class:`~agents.search.mapf.paths.AgentPath` objects by intersecting their integer code sets.

Time semantics are those of :mod:`agents.search.mapf.paths`: vertex, swap (unit time),
proximity and target conflicts; an agent stays parked at its goal after its final arrival.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from .constraints import (
    FOREVER,
    Constraint,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
)
from .instance import MapfInstance
from .paths import AgentPath

#: Conflict kinds.
VERTEX, EDGE, PROXIMITY, TARGET = 0, 1, 2, 3
KIND_NAMES = {VERTEX: "vertex", EDGE: "edge", PROXIMITY: "proximity", TARGET: "target"}

#: Conflict classes, in order of priority.
CARDINAL, SEMI_CARDINAL, NON_CARDINAL = 0, 1, 2

#: The two ways to resolve a conflict: ``[(agent, constraints), (agent, constraints)]``.
Branches = List[Tuple[int, Tuple[Constraint, ...]]]
#: A corridor, pseudo-corridor or rectangle split: ``(class, branches, per branch whether it
#: raises its agent's cost, kind)`` with kind ``"corridor"``, ``"pseudo"`` or ``"rectangle"``.
SymmetricSplit = Tuple[int, Branches, Tuple[bool, ...], str]


@dataclass(slots=True, eq=False)
class Conflict:
    """A conflict between agents ``a1`` and ``a2`` at step ``time``.

    - ``VERTEX``: both at (unit) / occupying (durative) node ``x1 == x2``.
    - ``EDGE``: ``a1`` moves ``x1 -> x2`` while ``a2`` moves ``x2 -> x1`` (unit time).
    - ``PROXIMITY``: ``a1`` at ``x1`` and ``a2`` at ``x2 != x1`` closer than the radius.
    - ``TARGET``: ``a1`` is parked at its goal ``x1`` (it has made its final arrival) while
      ``a2`` is at ``x2`` (``x1`` itself, or a node within the radius).

    ``cls`` (cardinal / semi-cardinal / non-cardinal), ``card1``/``card2`` (whether the
    branch constraining ``a1``/``a2`` must raise that agent's cost) and ``sym`` (a corridor or
    rectangle split) are filled in lazily by the high level; they depend only on the two
    agents' paths and constraints, which every node sharing the conflict has in common.
    """

    kind: int
    a1: int
    a2: int
    time: int
    x1: int
    x2: int
    cls: Optional[int] = None
    card1: bool = False
    card2: bool = False
    #: the symmetric (corridor / rectangle) split found for it, once looked for
    sym: Optional[SymmetricSplit] = None
    sym_done: bool = False

    def branches(self, target_reasoning: bool = True) -> Branches:
        """The two ways to resolve the conflict: ``[(agent, constraints), (agent, constraints)]``.

        Every conflict-free solution satisfies at least one branch, so splitting on them loses
        no solution.
        """
        a1, a2, t, x1, x2 = self.a1, self.a2, self.time, self.x1, self.x2
        if self.kind == EDGE:
            return [(a1, (EdgeConstraint(a1, x1, x2, t),)), (a2, (EdgeConstraint(a2, x2, x1, t),))]
        if self.kind == TARGET and target_reasoning:
            # either a1 is not parked yet at t, or it is (from some time <= t, for good), in which
            # case a2 may never be at x2 again from t on
            return [(a1, (LengthConstraint(a1, t),)), (a2, (RangeConstraint(a2, x2, t, FOREVER),))]
        return [(a1, (VertexConstraint(a1, x1, t),)), (a2, (VertexConstraint(a2, x2, t),))]

    def describe(self) -> str:
        """A one-line human-readable description."""
        name = KIND_NAMES[self.kind]
        if self.kind == EDGE:
            return (f"{name} conflict: agent {self.a1} {self.x1}->{self.x2} and agent {self.a2} "
                    f"{self.x2}->{self.x1} at t={self.time}")
        return f"{name} conflict: agent {self.a1} at {self.x1} and agent {self.a2} at {self.x2} at t={self.time}"


def pair_conflicts(
    a: int, pa: AgentPath, b: int, pb: AgentPath, inst: MapfInstance, all_times: bool = True
) -> List[Conflict]:
    """All conflicts between the paths of agents ``a`` and ``b``, sorted by time.

    At most one conflict per time step is reported. Target conflicts (one agent parked at its
    goal) are reported once per direction, at the earliest time.
    """
    N = inst.n_nodes
    found: Dict[int, Conflict] = {}
    # both agents still moving
    common = pa.code_set.intersection(pb.codes)
    for code in common:
        t, x = divmod(code, N)
        if t not in found:
            found[t] = Conflict(VERTEX, a, b, t, x, x)
    if pa.swap_set and pb.move_codes:
        for code in pa.swap_set.intersection(pb.move_codes):
            tw, u = divmod(code, N)
            t, w = divmod(tw, N)
            # b moves w -> u at t, so a moves u -> w at t
            if t not in found:
                found[t] = Conflict(EDGE, a, b, t, u, w)
    near = inst.near
    if near is not None:
        if pa.near_codes:
            for code in pb.code_set.intersection(pa.near_codes):
                t, y = divmod(code, N)
                if t in found:
                    continue
                for x in pa.occupied(t):
                    if y in near[x]:
                        found[t] = Conflict(PROXIMITY, a, b, t, x, y)
                        break
    # one agent parked at its goal, the other still moving
    for (p, q, ip, iq) in ((pb, pa, b, a), (pa, pb, a, b)):
        # p parked at its goal from p.cost on; q moving before q.cost
        g, Tp = p.goal, p.cost
        if Tp >= q.cost:
            continue
        watch = {g} if near is None else ({g} | set(near[g]))
        if not (watch & q.node_set):
            continue
        for k in range(Tp, q.cost):
            hit = None
            for x in q.occupied(k):
                if x in watch:
                    hit = x
                    break
            if hit is not None:
                c = Conflict(TARGET, ip, iq, k, g, hit)
                old = found.get(k)
                if old is None or old.kind != TARGET:
                    found[k] = c
                break
    return [found[t] for t in sorted(found)]
