"""Constraints of Conflict-Based Search (CBS), over integer node ids.

A constraint forbids one agent something; the high level adds one (or a pair) per branch.
Times are integer plan steps. Two time models share the same constraint classes:

- **unit time**: an agent is *at* a node at every integer time ``t``; a
  :class:`VertexConstraint` forbids being at ``node`` at time ``t``.
- **durative edges**: what counts is *occupancy* of a node during the step ``[t, t + 1)``: an
  agent waiting at ``v`` occupies ``v``; an agent traversing ``u -> v`` (taking ``d`` steps)
  occupies both ``u`` and ``v`` during each of those steps. A :class:`VertexConstraint`
  forbids occupying ``node`` during step ``[t, t + 1)``.

Constraint sets are persistent linked lists (:class:`ConstraintSet`): a child node of the
constraint tree shares its parent's set and adds one link. Each set also carries its
``content`` as a frozenset, which caches (compiled constraints, MDDs, pair sub-problems) are
keyed by: nodes reached by adding the same constraints in another order share their entries.

:func:`compile_constraints` turns one agent's set into the integer lookup tables the low-level
searches read (:class:`CompiledConstraints`).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Dict, Iterator, List, Optional, Set, Tuple, Union

#: The ``end`` of a :class:`RangeConstraint` that never expires.
FOREVER = 1 << 40


@dataclass(frozen=True, slots=True)
class VertexConstraint:
    """``agent`` must not be at (unit time) / occupy (durative) ``node`` at step ``time``."""

    agent: int
    node: int
    time: int


@dataclass(frozen=True, slots=True)
class EdgeConstraint:
    """``agent`` must not start the move ``u -> v`` at ``time`` (unit time: swap conflicts)."""

    agent: int
    u: int
    v: int
    time: int


@dataclass(frozen=True, slots=True)
class RangeConstraint:
    """``agent`` must not be at / occupy ``node`` at any step in ``[start, end]`` (inclusive).

    ``end=FOREVER`` is the constraint of target reasoning: "never again at ``node`` from
    ``start`` on", imposed on an agent that would run into another agent parked at its goal.
    """

    agent: int
    node: int
    start: int
    end: int = FOREVER


@dataclass(frozen=True, slots=True)
class LengthConstraint:
    """``agent`` must make its final arrival at its goal strictly later than ``time``.

    This is the other branch of target reasoning: the agent may not be parked at its goal at
    ``time`` yet.
    """

    agent: int
    time: int


@dataclass(frozen=True, slots=True)
class DeadlineConstraint:
    """``agent`` must make its final arrival at its goal at or before ``time`` (unit time).

    The agent is then at its goal at every step from ``time`` on. It is the branch of the
    disjoint target split in which an agent is parked at its goal from ``time`` at the latest,
    the complement of ``LengthConstraint(agent, time)``.
    """

    agent: int
    time: int


Constraint = Union[VertexConstraint, EdgeConstraint, RangeConstraint, LengthConstraint, DeadlineConstraint]

#: ``(TF, hF, late)`` of reaching a node while some nodes close for good (see
#: :func:`agents.search.mapf.successors.cut_off`): the time from which all are closed, the distances
#: avoiding them, and per node the last time at which being there can still lead to the target.
CutOff = Tuple[int, List[int], List[int]]

_keys = itertools.count(1)
_NO_CONSTRAINTS: frozenset = frozenset()


class ConstraintSet:
    """An immutable set of one agent's constraints, as a linked list sharing its parent's links.

    ``key`` is unique per set object; ``content`` is the constraints as a frozenset, equal for
    two sets that hold the same constraints however they were added (what caches of results
    that depend only on the constraints are keyed by); ``size`` is the number of constraints.
    """

    __slots__ = ("constraint", "parent", "key", "size", "content")

    def __init__(self, constraint: Optional[Constraint] = None, parent: Optional["ConstraintSet"] = None):
        self.constraint = constraint
        self.parent = parent
        self.key = next(_keys)
        self.size: int = 0 if constraint is None else (parent.size if parent is not None else 0) + 1
        base = parent.content if parent is not None else _NO_CONSTRAINTS
        self.content: frozenset = base if constraint is None else base | {constraint}

    def add(self, *constraints: Constraint) -> "ConstraintSet":
        """A new set holding this set's constraints plus ``constraints``."""
        out = self
        for c in constraints:
            out = ConstraintSet(c, out)
        return out

    def __iter__(self) -> Iterator[Constraint]:
        """The constraints, oldest first."""
        items: List[Constraint] = []
        node: Optional[ConstraintSet] = self
        while node is not None and node.constraint is not None:
            items.append(node.constraint)
            node = node.parent
        return iter(reversed(items))

    def __len__(self) -> int:
        return self.size

    def __repr__(self) -> str:
        return f"ConstraintSet({list(self)!r})"


EMPTY = ConstraintSet()


@dataclass
class CompiledConstraints:
    """One agent's constraints in the form the low-level search reads (hashable integer codes).

    Attributes:
        vset: codes ``t * N + v`` of forbidden (node, step) pairs.
        eset: codes ``(t * N + u) * N + v`` of forbidden moves ``u -> v`` starting at ``t``.
        forever: node -> first step from which the node is forbidden for good.
        goal_min: the final arrival at the goal must be strictly later than this (-1: none).
        t_static: after this step the constraints no longer change with time.
        impossible: the constraints can never be met (e.g. the goal is forbidden for good).
        deadline: the final arrival must be at or before this (:data:`FOREVER`: none).
        ranges: the finite range constraints ``(node, start, end)`` (they sharpen the heuristic).
        landmarks, forever_h, cut_offs: caches the low-level searches fill in on first use
            (see :mod:`agents.search.mapf.successors`); not part of the comparison.
    """

    vset: Set[int]
    eset: Set[int]
    forever: Dict[int, int]
    goal_min: int
    t_static: int
    impossible: bool = False
    deadline: int = FOREVER
    ranges: List[Tuple[int, int, int]] = field(default_factory=list)
    landmarks: Optional[Dict[int, List[Tuple[int, int, int]]]] = field(default=None, repr=False, compare=False)
    forever_h: Optional[CutOff] = field(default=None, repr=False, compare=False)
    cut_offs: Optional[Dict[Tuple[int, frozenset], CutOff]] = field(default=None, repr=False, compare=False)


def compile_constraints(cons: ConstraintSet, n_nodes: int, goal: int) -> CompiledConstraints:
    """Turn an agent's constraint set into lookup tables for the low-level search."""
    vset: Set[int] = set()
    eset: Set[int] = set()
    forever: Dict[int, int] = {}
    goal_min = -1
    t_static = 0
    impossible = False
    ranges: List[Tuple[int, int, int]] = []
    deadline = FOREVER
    N = n_nodes
    for c in cons:
        if isinstance(c, VertexConstraint):
            vset.add(c.time * N + c.node)
            t_static = max(t_static, c.time)
            if c.node == goal:
                goal_min = max(goal_min, c.time)
        elif isinstance(c, EdgeConstraint):
            eset.add((c.time * N + c.u) * N + c.v)
            t_static = max(t_static, c.time + 1)
        elif isinstance(c, RangeConstraint):
            if c.end >= FOREVER:
                prev = forever.get(c.node)
                forever[c.node] = c.start if prev is None else min(prev, c.start)
                t_static = max(t_static, c.start)
                if c.node == goal:
                    impossible = True
            else:
                ranges.append((c.node, c.start, c.end))
                for t in range(c.start, c.end + 1):
                    vset.add(t * N + c.node)
                t_static = max(t_static, c.end)
                if c.node == goal:
                    goal_min = max(goal_min, c.end)
        elif isinstance(c, LengthConstraint):
            goal_min = max(goal_min, c.time)
        elif isinstance(c, DeadlineConstraint):
            deadline = min(deadline, c.time)
        else:  # pragma: no cover - guarded by the type
            raise TypeError(f"unknown constraint {c!r}")
    t_static = max(t_static, goal_min + 1)
    if deadline < FOREVER:
        t_static = max(t_static, deadline + 1)
        if deadline <= goal_min:
            impossible = True
    return CompiledConstraints(vset, eset, forever, goal_min, t_static, impossible, deadline, ranges)
