"""Timed paths of single agents, in the integer form conflict detection and the searches read.

States are ``(node, time)`` pairs encoded as integers ``time * N + node``. An
:class:`AgentPath` keeps one agent's events and the integer code sets that let
:func:`~agents.search.mapf.conflicts.pair_conflicts` intersect two paths at C speed; a
:class:`Reservation` summarises the other agents' paths for the conflict-avoiding tie-breaking
of the low-level searches.

Time semantics:

- unit time: an agent is at one node at each integer time; vertex, swap, proximity (at integer
  times) and target conflicts.
- durative: during each step ``[k, k + 1)`` an agent *occupies* one node (waiting) or both ends
  of the edge it is traversing. Two agents conflict when their occupied nodes coincide or are
  near. This is deliberately conservative: an agent may not enter a node during the step
  another agent is leaving it, and swaps or crossings of edges are vertex conflicts.

In both models an agent stays at its goal forever after its final arrival (it is *parked*).
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Set, Tuple

from .constraints import (
    Constraint,
    DeadlineConstraint,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
)
from .instance import MapfInstance


class AgentPath:
    """One agent's timed path and the integer indexes used by conflict detection.

    ``events`` lists ``(node, time)`` at every time the agent is at a node: each time step
    under unit time; arrivals and each waiting step under the durative model. The last event is
    the final arrival at the goal; ``cost`` is its time.
    """

    __slots__ = ("events", "cost", "goal", "steps", "codes", "code_set", "move_codes", "swap_set",
                 "node_set", "near_codes", "occ", "lb")

    def __init__(self, events: List[Tuple[int, int]], inst: MapfInstance, lb: Optional[int] = None):
        N = inst.n_nodes
        self.events = events
        self.goal, self.cost = events[-1]
        T = self.cost
        #: lower bound on this agent's optimal cost under its constraints (focal search)
        self.lb = T if lb is None else lb
        #: unit time: the node at every time ``0..cost`` (``None`` under the durative model)
        self.steps: Optional[List[int]]
        #: durative: per step ``k < cost``, ``(node, other end or the same node)`` (``None`` under unit time)
        self.occ: Optional[List[Tuple[int, int]]]
        #: codes ``(t * N + w) * N + u`` of the reversed moves (unit time: swap detection)
        self.swap_set: Set[int]
        #: codes of the nodes near the occupied ones (``None`` without proximity)
        self.near_codes: Optional[List[int]]
        occ_pairs: List[Tuple[int, int]]
        if inst.unit:
            steps = [v for v, _ in events]
            self.steps = steps
            self.occ = None
            self.codes = [t * N + steps[t] for t in range(T)]
            mc = []
            sw = []
            for t in range(T):
                u, w = steps[t], steps[t + 1]
                if u != w:
                    mc.append((t * N + u) * N + w)
                    sw.append((t * N + w) * N + u)
            self.move_codes = mc
            self.swap_set = set(sw)
            self.node_set = set(steps)
            occ_pairs = [(t, steps[t]) for t in range(T)]
        else:
            occ: List[Tuple[int, int]] = []  # per step k < T: (node, other end or same)
            for (u, t0), (v, t1) in zip(events, events[1:]):
                for _ in range(t0, t1):
                    occ.append((u, v))
            self.occ = occ
            self.steps = None
            codes = []
            occ_pairs = []
            for k, (u, v) in enumerate(occ):
                codes.append(k * N + u)
                occ_pairs.append((k, u))
                if v != u:
                    codes.append(k * N + v)
                    occ_pairs.append((k, v))
            self.codes = codes
            self.move_codes = []
            self.swap_set = set()
            self.node_set = {v for v, _ in events}
        self.code_set = set(self.codes)
        near = inst.near
        if near is not None:
            nc: List[int] = []
            for k, x in occ_pairs:
                base = k * N
                nc.extend(base + y for y in near[x])
            self.near_codes = nc
        else:
            self.near_codes = None

    def node_at(self, t: int) -> int:
        """Unit time: the node at time ``t`` (the goal after arrival)."""
        steps = self.steps
        if steps is None:
            raise ValueError("node_at is defined under unit time only; use occupied()")
        return steps[t] if t < len(steps) else self.goal

    def occupied(self, k: int) -> Tuple[int, ...]:
        """Nodes occupied during step ``k`` (durative) / at time ``k`` (unit)."""
        occ = self.occ
        if occ is None:
            return (self.node_at(k),)
        if k >= self.cost:
            return (self.goal,)
        u, v = occ[k]
        return (u,) if u == v else (u, v)


#: how the low-level searches spread routes apart (:class:`Reservation`'s ``spread``)
SPREAD_MODES = ("off", "routes", "near")


def spread_mode(value: str) -> str:
    """``value`` if it is one of :data:`SPREAD_MODES`, else a ``ValueError`` naming them."""
    if not isinstance(value, str) or value not in SPREAD_MODES:
        raise ValueError(f"spread must be one of {', '.join(map(repr, SPREAD_MODES))}, got {value!r}")
    return value


class Reservation:
    """The other agents' paths as integer sets, for conflict-avoiding tie-breaking.

    ``spread`` (durative model only) fills :attr:`places`: ``"routes"`` with every node the other
    paths visit, at any time, ``"near"`` with those and the nodes near them (``"off"``: empty).
    The low-level searches then prefer, of paths equal in cost and conflicts, those that enter
    fewer of those places (see :func:`~agents.search.mapf.successors.make_successors`).
    """

    __slots__ = ("occ", "moves", "parked", "horizon", "places")

    def __init__(self, paths: Sequence[Optional[AgentPath]], exclude: int, inst: MapfInstance,
                 spread: str = "off"):
        occ: Set[int] = set()
        moves: Set[int] = set()
        parked: Dict[int, int] = {}
        horizon = 0
        near = inst.near
        for b, p in enumerate(paths):
            if b == exclude or p is None:
                continue
            occ.update(p.codes)
            if p.move_codes:
                moves.update(p.move_codes)
            if p.near_codes is not None:
                occ.update(p.near_codes)
            T = p.cost
            if T > horizon:
                horizon = T
            for x in ([p.goal] + near[p.goal]) if near is not None else (p.goal,):
                old = parked.get(x)
                if old is None or T < old:
                    parked[x] = T
        self.occ = occ
        self.moves = moves
        self.parked = parked
        self.horizon = horizon
        places: Set[int] = set()
        if spread != "off" and not inst.unit:  # checked once by the solver (spread_mode), not per search
            for b, p in enumerate(paths):
                if b != exclude and p is not None:
                    places.update(p.node_set)
            if spread == "near" and near is not None:
                for x in list(places):
                    places.update(near[x])
        #: nodes on (``spread="routes"``) or also near (``"near"``) the other paths at any time
        self.places = places



def satisfies(path: AgentPath, c: Constraint) -> bool:
    """Unit time: whether a path (parked at its goal after its arrival) meets constraint ``c``."""
    T = path.cost
    steps = path.steps
    if steps is None:
        raise ValueError("satisfies is defined under unit time only")
    if isinstance(c, VertexConstraint):
        return (steps[c.time] if c.time < T else path.goal) != c.node
    if isinstance(c, EdgeConstraint):
        t = c.time
        if t >= T:
            return True
        return not (steps[t] == c.u and steps[t + 1] == c.v)
    if isinstance(c, RangeConstraint):
        if c.node == path.goal and c.end >= T and c.end >= c.start:
            return False
        for t in range(c.start, min(c.end, T - 1) + 1):
            if steps[t] == c.node:
                return False
        return True
    if isinstance(c, LengthConstraint):
        return T > c.time
    if isinstance(c, DeadlineConstraint):
        return T <= c.time
    raise TypeError(f"unknown constraint {c!r}")
