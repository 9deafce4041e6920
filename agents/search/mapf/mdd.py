"""Multi-valued decision diagrams (MDDs): every state on some cheapest path of one agent.

The high level classifies conflicts with them (cardinal when every cheapest path of both
agents meets the conflict), the dependency-graph heuristics merge two of them
(:func:`mdds_dependent`), and rectangle reasoning reads their single-node levels. States are
coded ``time * N + node`` as in the low-level searches.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Set, Tuple

import numpy as np

from .constraints import CompiledConstraints
from .instance import MapfInstance
from .successors import goal_successors, make_successors

#: The ``end`` of :meth:`MDD.avoidable` when none is given: past every time of a plan.
_NO_END = 1 << 60


class MDD:
    """Multi-valued decision diagram: every (node, time) state on some cheapest path.

    Built for an agent, its constraints and its optimal cost ``C``. ``levels[t]`` is the set of
    nodes an optimal path can be at (unit time) at time ``t``; ``must[k]`` is the set of nodes
    *every* optimal path occupies at step ``k`` (durative) or is at (unit). ``edges`` lists the
    kept transitions ``(v, t, w, t2)``.
    """

    __slots__ = ("cost", "edges", "levels", "must", "_children", "start", "goal", "N", "_singles", "_kids")

    def __init__(self, cost: int, edges: List[Tuple[int, int, int, int]], start: int, goal: int, N: int, unit: bool):
        self.cost = cost
        self.edges = edges
        self.start = start
        self.goal = goal
        self.N = N
        self._singles: Optional[List[Tuple[int, int]]] = None
        self._kids: Optional[Dict[int, List[int]]] = None
        self._children: Optional[Dict[int, List[int]]] = None
        levels: List[Set[int]] = [set() for _ in range(cost + 1)]
        levels[0].add(start)
        levels[cost].add(goal)
        for e in edges:
            levels[e[3]].add(e[2])
        self.levels = levels
        if unit:
            self.must = [lv if len(lv) == 1 else set() for lv in levels]
        else:
            must: List[Optional[Set[int]]] = [None] * cost
            for v, t, w, t2 in edges:
                pair = {v, w}
                for k in range(t, t2):
                    m = must[k]
                    must[k] = set(pair) if m is None else (m & pair)
            self.must = [m if m is not None else set() for m in must]

    def avoidable(self, node: int, start: int, unit: bool, end: Optional[int] = None) -> bool:
        """Whether some optimal path is never at / never occupies ``node`` at a step in ``[start, end]``.

        ``end=None`` means for ever (the agent stays parked at its goal after ``cost``).
        """
        N = self.N
        target = self.cost * N + self.goal
        hi = end if end is not None else _NO_END
        if self.goal == node and hi >= self.cost:
            return False  # parked there from ``cost`` on
        if start <= 0 <= hi and self.start == node:
            return False
        if unit:
            # read the levels first: no level in the window holds the node (some optimal path,
            # indeed every one, keeps off it), or one holds only the node (none does)
            levels = self.levels
            last = min(hi, self.cost)
            lo = max(start, 0)
            touched = False
            for t in range(lo, last + 1):
                lv = levels[t]
                if node in lv:
                    if len(lv) == 1:
                        return False
                    touched = True
            if not touched:
                return True
        stack = [self.start]
        seen = {self.start}
        while stack:
            code = stack.pop()
            if code == target:
                return True
            t, v = divmod(code, N)
            for nxt in self.children.get(code, ()):
                if nxt in seen:
                    continue
                t2, w = divmod(nxt, N)
                if unit:
                    if w == node and start <= t2 <= hi:
                        continue
                else:
                    # occupies v and w during steps t .. t2 - 1
                    if (w == node or v == node) and t2 - 1 >= start and t <= hi:
                        continue
                seen.add(nxt)
                stack.append(nxt)
        return False

    @property
    def children(self) -> Dict[int, List[int]]:
        """State code ``t * N + v`` -> the codes ``t2 * N + w`` of its children (built on first use)."""
        if self._children is None:
            N = self.N
            children: Dict[int, List[int]] = {}
            for v, t, w, t2 in self.edges:
                k = t * N + v
                lst = children.get(k)
                if lst is None:
                    children[k] = [t2 * N + w]
                else:
                    lst.append(t2 * N + w)
            self._children = children
        return self._children

    def kids(self) -> Dict[int, List[int]]:
        """State code ``t * N + v`` -> the nodes of its children (built on first use)."""
        if self._kids is None:
            N = self.N
            kids: Dict[int, List[int]] = {}
            for v, t, w, _ in self.edges:
                k = t * N + v
                lst = kids.get(k)
                if lst is None:
                    kids[k] = [w]
                else:
                    lst.append(w)
            self._kids = kids
        return self._kids

    def singletons(self) -> List[Tuple[int, int]]:
        """``(time, node)`` of every level with a single node (unit time)."""
        if self._singles is None:
            self._singles = [(t, next(iter(lv))) for t, lv in enumerate(self.levels) if len(lv) == 1]
        return self._singles


def build_mdd(inst: MapfInstance, agent: int, cc: CompiledConstraints, cost: int) -> MDD:
    """The MDD of ``agent`` under ``cc`` for its optimal cost ``cost``.

    A forward pass, time by time, keeps the moves from the states reached so far that can still
    arrive at the goal by ``cost`` (and at ``cost`` only at the goal); a backward pass keeps those
    of them that lead to the goal at ``cost``.
    """
    N = inst.n_nodes
    s, g = inst.starts[agent], inst.goals[agent]
    successors = make_successors(inst, cc, None, inst.h[agent], frozenset(), cost + 1, f_limit=cost,
                                 successors_h=goal_successors(inst, agent))
    fwd: List[Tuple[int, int, int, int]] = []
    layers: Dict[int, Set[int]] = {0: {s}}
    for t in range(cost):
        nodes = layers.get(t)
        if not nodes:
            continue
        for v in sorted(nodes):
            for code, f, _, hw in successors(t * N + v, v, t, 0):
                nt, w = f - hw, code % N
                if nt == cost and w != g:
                    continue
                layer = layers.get(nt)
                if layer is None:
                    layers[nt] = {w}
                else:
                    layer.add(w)
                fwd.append((v, t, w, nt))
    alive = {cost * N + g}
    kept = []
    for v, t, w, nt in reversed(fwd):
        if nt * N + w in alive:
            alive.add(t * N + v)
            kept.append((v, t, w, nt))
    kept.reverse()
    return MDD(cost, kept, s, g, N, inst.unit)


def prune_mdd(m: MDD, cc: CompiledConstraints) -> Optional[MDD]:
    """Unit time: the MDD of the same agent and cost under constraints ``cc`` that include the
    ones ``m`` was built under (``None`` if no path of that cost is left).

    Every path of cost ``m.cost`` that meets ``cc`` meets the older constraints too, so it is a
    path of ``m``: dropping the edges ``cc`` forbids and trimming what no longer joins the start
    to the goal gives exactly the MDD :func:`build_mdd` would build, at a fraction of the work.
    """
    N = m.N
    vset, eset, forever = cc.vset, cc.eset, cc.forever
    alive = {m.start}
    fwd = []
    for e in m.edges:  # in order of time
        v, t, w, t2 = e
        if t * N + v not in alive or (t2 * N + w) in vset:
            continue
        if w != v and ((t * N + v) * N + w) in eset:
            continue
        if forever:
            fw = forever.get(w)
            if fw is not None and t2 >= fw:
                continue
        alive.add(t2 * N + w)
        fwd.append(e)
    target = m.cost * N + m.goal
    if target not in alive:
        return None
    back = {target}
    kept = []
    for e in reversed(fwd):
        v, t, w, t2 = e
        if t2 * N + w in back:
            back.add(t * N + v)
            kept.append(e)
    kept.reverse()
    return MDD(m.cost, kept, m.start, m.goal, N, True)


def mdds_dependent(m1: MDD, m2: MDD, near_mat: Optional[np.ndarray] = None,
                   probe_states: Optional[int] = None) -> bool:
    """Unit time: True if no pair of optimal paths (one from each MDD) is conflict-free.

    First a short depth-first probe over the joint states of both MDDs (an agent past its
    cost stays at its goal) looks for one conflict-free pair of paths, which independent agents
    (most of the pairs asked about) have in plenty; when it gives up after a few states per
    time step (``probe_states``, default ``4 * T + 32`` for the longer cost ``T``), a
    breadth-first search over the joint states, level by level, decides. Used by the
    dependency graph heuristics.
    """
    N = m1.N
    T = max(m1.cost, m2.cost)
    if T == 0:
        return False
    k1, k2 = m1.kids(), m2.kids()
    c1, c2 = m1.cost, m2.cost
    g1, g2 = (m1.goal,), (m2.goal,)
    empty: Tuple[int, ...] = ()

    def joint(t: int, a: int, b: int) -> List[Tuple[int, int]]:
        na = k1.get(t * N + a, empty) if t < c1 else g1
        nb = k2.get(t * N + b, empty) if t < c2 else g2
        out = []
        for x in na:
            for y in nb:
                if x == y or (x == b and y == a):
                    continue
                if near_mat is not None and near_mat[x, y]:
                    continue
                out.append((x, y))
        return out

    # the probe: frames [time, children, next child]; a joint state seen before has no
    # conflict-free continuation (time only grows, so it is not on the stack)
    NN = N * N
    seen: Set[int] = set()
    budget = 4 * T + 32 if probe_states is None else probe_states
    stack: List[list] = [[0, joint(0, m1.start, m2.start), 0]] if budget > 0 else []
    while stack and budget > 0:
        frame = stack[-1]
        t, kids, k = frame
        if k == len(kids):
            stack.pop()
            continue
        frame[2] = k + 1
        x, y = kids[k]
        nt = t + 1
        if nt == T:
            return False
        code = nt * NN + x * N + y
        if code in seen:
            continue
        seen.add(code)
        budget -= 1
        stack.append([nt, joint(nt, x, y), 0])
    if not stack and budget > 0:
        return True  # every joint state explored: none reaches the end
    cur = {(m1.start, m2.start)}
    for t in range(T):
        nxt: Set[Tuple[int, int]] = set()
        for a, b in cur:
            nxt.update(joint(t, a, b))
        if not nxt:
            return True
        cur = nxt
    return not cur
