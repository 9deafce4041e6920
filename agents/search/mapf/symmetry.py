"""Pairwise symmetry reasoning for CBS (unit time): corridor, pseudo-corridor and rectangle conflicts.

Plain CBS resolves a conflict with one vertex constraint per branch. When two agents meet
head-on in a corridor, or cross each other's paths in an open area of a grid, there are
exponentially many equally good ways to resolve the meeting and plain CBS explores them one
by one. The splits below resolve the whole symmetric family at once. All are *sound*: every
conflict-free solution satisfies one of the two branches (proofs in the docstrings), so
optimality is kept.

- **Corridor** (any graph whose corridor edges go both ways): a chain ``A = x_0, x_1, ..., x_m,
  x_{m+1} = B`` whose inner nodes have exactly two neighbours. If agent 1 crosses it from ``A``
  to ``B`` and agent 2 from ``B`` to ``A``, one of them must let the other through first.
- **Pseudo-corridor** (any graph): two agents meeting head-on at a node ``x`` (or swapping
  along an edge) where both agents' MDDs force the meeting, ``x`` having any number of
  neighbours: the same split as a corridor ``A - x - B`` of length one (or ``A - B``), its
  bounds sized so that an agent at its far end early enough must have come through ``x``
  from its near end (:meth:`Corridors.pseudo_split`).
- **Rectangle** (4-connected grids, node coordinates given): two agents whose cheapest paths
  all move monotonically through a common rectangle, one crossing it top-to-bottom and the other
  left-to-right, always meet; barrier constraints along two borders force one to detour.
"""
from __future__ import annotations

from collections import deque
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import dijkstra

from .conflicts import EDGE, VERTEX, Branches, Conflict
from .constraints import RangeConstraint, VertexConstraint
from .instance import UNREACHABLE, MapfInstance
from .mdd import MDD
from .paths import AgentPath


class Corridors:
    """Maximal chains of two-neighbour nodes of a graph and the distances corridor reasoning needs."""

    def __init__(self, inst: MapfInstance):
        self.inst = inst
        n = inst.n_nodes
        out = [set(s[1:]) for s in inst.succ]
        inn: List[set] = [set() for _ in range(n)]
        for u in range(n):
            for v in out[u]:
                inn[v].add(u)
        inner = [len(out[v]) == 2 and out[v] == inn[v] for v in range(n)]
        #: node -> corridor id (inner nodes only)
        self.corridor_of: Dict[int, int] = {}
        #: per corridor: (inner nodes from the A side, A, B)
        self.corridors: List[Tuple[List[int], int, int]] = []
        #: per corridor: its inner nodes as a frozenset
        self.inner_sets: List[frozenset] = []
        for v in range(n):
            if not inner[v] or v in self.corridor_of:
                continue
            # walk both ways from v to the first non-inner nodes
            chain = [v]
            ends = []
            cyclic = False
            for first in sorted(out[v]):
                prev, cur = v, first
                side = []
                while inner[cur] and cur != v:
                    side.append(cur)
                    nxt = [w for w in out[cur] if w != prev]
                    prev, cur = cur, nxt[0]
                if cur == v:
                    cyclic = True
                    break
                ends.append((side, cur))
            if cyclic or len(ends) != 2:
                for x in chain:
                    self.corridor_of[x] = -1
                continue
            (side_a, a), (side_b, b) = ends
            if a == b:
                for x in side_a + chain + side_b:
                    self.corridor_of[x] = -1
                continue
            nodes = list(reversed(side_a)) + chain + side_b
            cid = len(self.corridors)
            self.corridors.append((nodes, a, b))
            self.inner_sets.append(frozenset(nodes))
            for x in nodes:
                self.corridor_of[x] = cid
        self._from_start: Optional[np.ndarray] = None
        self._avoiding: Dict[Tuple[int, int], Tuple[int, int]] = {}
        #: per node, the other nodes with an edge into it
        self.pred: List[List[int]] = [sorted(s) for s in inn]

    def from_start(self, agent: int) -> np.ndarray:
        """Shortest distances (steps) from the agent's start to every node."""
        if self._from_start is None:
            d = dijkstra(self.inst.durations, directed=True, indices=list(self.inst.starts), unweighted=True)
            k = len(self.inst.starts)
            self._from_start = np.where(np.isfinite(d), d, UNREACHABLE).astype(np.int64).reshape(k, -1)
        return self._from_start[agent]

    def avoiding(self, agent: int, cid: int) -> Tuple[int, int]:
        """Distances from the agent's start to the corridor's ends ``(A, B)`` without using its inner nodes."""
        key = (agent, cid)
        val = self._avoiding.get(key)
        if val is None:
            nodes, a, b = self.corridors[cid]
            blocked = set(nodes)
            s = self.inst.starts[agent]
            dist = {s: 0}
            queue = deque([s])
            succ = self.inst.succ
            found = 0
            while queue and found < 2:
                u = queue.popleft()
                du = dist[u]
                for w in succ[u]:
                    if w in dist or w in blocked:
                        continue
                    dist[w] = du + 1
                    if w == a or w == b:
                        found += 1
                    queue.append(w)
            val = (dist.get(a, UNREACHABLE), dist.get(b, UNREACHABLE))
            self._avoiding[key] = val
        return val

    # ------------------------------------------------------------------ the split
    def split(self, c: Conflict, i1: int, p1: AgentPath, i2: int, p2: AgentPath,
              earliest: Optional[Callable[[int, int, Optional[int]], int]] = None) -> Optional[Branches]:
        """Corridor constraints for a vertex/edge conflict inside a corridor, or ``None``.

        Branches: ``agent1 not at B during [0, U1]`` / ``agent2 not at A during [0, U2]`` with
        ``U1 = min(d2(A) + k, d1'(B) - 1)`` and ``U2 = min(d1(B) + k, d2'(A) - 1)``, where ``k``
        is the number of edges from A to B, ``d`` a lower bound on the agent's earliest arrival
        (its distance from its start, or, through ``earliest(agent, node, corridor_or_None)``,
        the earliest arrival under its constraints) and ``d'`` the same avoiding the corridor.
        Soundness: if agent 1 is at B by ``U1 < d1'(B)`` its first arrival at B came through the
        corridor from A, and likewise agent 2's at A. If the two crossings overlap in time they
        meet inside the corridor (vertex or swap conflict); if agent 1 crosses first, agent 2 can
        start only after agent 1 left B, so it reaches A at or after ``d1(B) + k + 1 > U2``;
        symmetrically if agent 2 goes first.
        """
        if c.kind not in (VERTEX, EDGE):
            return None
        cid = self.corridor_of.get(c.x1, -1)
        if cid < 0 and c.kind == EDGE:
            cid = self.corridor_of.get(c.x2, -1)
        if cid < 0:
            return None
        nodes, a_end, b_end = self.corridors[cid]
        inner = set(nodes)
        k = len(nodes) + 1
        ends = []
        for p in (p1, p2):
            steps = p.steps
            if steps is None:
                return None
            T = p.cost
            t = c.time
            if t >= T:
                return None
            i = t
            while i >= 0 and steps[i] in inner:
                i -= 1
            if i < 0:
                return None
            j = t + 1
            while j <= T and steps[j] in inner:
                j += 1
            if j > T:
                return None
            entry, leave = steps[i], steps[j]
            if entry == leave or entry not in (a_end, b_end) or leave not in (a_end, b_end):
                return None
            ends.append((entry, leave, j))
        (en1, ex1, tau1), (en2, ex2, tau2) = ends
        if en1 != ex2 or ex1 != en2:
            return None
        A, B = en1, ex1
        inst = self.inst
        s1, s2 = inst.starts[i1], inst.starts[i2]
        if s1 in inner or s2 in inner or s1 == B or s2 == A:
            return None
        av1 = self.avoiding(i1, cid)
        av2 = self.avoiding(i2, cid)
        d1p_B = av1[1] if B == b_end else av1[0]
        d2p_A = av2[0] if A == a_end else av2[1]
        d2_A = int(self.from_start(i2)[A])
        d1_B = int(self.from_start(i1)[B])
        u1 = min(d2_A + k, d1p_B - 1)
        u2 = min(d1_B + k, d2p_A - 1)
        if (tau1 > u1 or tau2 > u2) and earliest is not None:
            # sharpen the bounds with the agents' constraints
            if tau1 > d2_A + k or tau2 > d2p_A - 1:
                d2_A = max(d2_A, earliest(i2, A, None))
                if tau2 > d2p_A - 1:
                    d2p_A = max(d2p_A, earliest(i2, A, cid))
            if tau2 > d1_B + k or tau1 > d1p_B - 1:
                d1_B = max(d1_B, earliest(i1, B, None))
                if tau1 > d1p_B - 1:
                    d1p_B = max(d1p_B, earliest(i1, B, cid))
            u1 = min(d2_A + k, d1p_B - 1)
            u2 = min(d1_B + k, d2p_A - 1)
        if tau1 > u1 or tau2 > u2:
            return None  # the split would not cut the current paths
        return [(i1, (RangeConstraint(i1, B, 0, u1),)), (i2, (RangeConstraint(i2, A, 0, u2),))]

    def pseudo_split(self, c: Conflict, i1: int, m1: MDD, i2: int, m2: MDD,
                     earliest: Optional[Callable[[int, int, Optional[int]], int]] = None) -> Optional[Branches]:
        """Pseudo-corridor constraints for a head-on vertex or swap conflict anywhere, or ``None``.

        The conflict must be head-on and forced: a vertex conflict at ``(x, t)`` where every
        cheapest path of agent 1 is at ``A``, ``x``, ``B`` at ``t - 1``, ``t``, ``t + 1`` (its
        MDD ``m1`` has those single-node levels) and every cheapest path of agent 2 at ``B``,
        ``x``, ``A`` (``m2``), with ``A``, ``x``, ``B`` distinct; or a swap conflict, agent 1
        moving ``A -> B`` and agent 2 ``B -> A`` at ``t``, both forced by their MDDs. The cells
        between ``A`` and ``B`` (``x``, or none) are treated as a corridor of ``k`` edges
        (``k = 2``, or ``1``) even though ``x`` may have more than two neighbours. Branches, as
        for a corridor: ``agent1 not at B during [0, U1]`` / ``agent2 not at A during [0, U2]``
        with ``U1 = min(L2 + k, E1 - 1)``, ``U2 = min(L1 + k, E2 - 1)``.

        The bounds come from per-node lower bounds ``d_i(v)`` on agent ``i``'s arrival at ``v``
        (its distance from its start, or with ``earliest(agent, node, None)`` the earliest
        arrival under its constraints, which bounds every prefix of a path meeting them).
        Call a first arrival of agent 1 at ``B`` *through the pseudo-corridor* when it steps
        ``A -> x``, stays at ``x``, then steps ``x -> B`` (swap case: steps ``A -> B``); such an
        arrival is at or after ``L1 = max(d1(B), d1(A) + k)``. Any other first arrival at ``B``
        enters ``B`` from a node ``y`` other than ``x`` (swap case: other than ``A``), or enters
        it from ``x`` after entering ``x`` from some ``z`` other than ``A`` and ``B``, so it is at
        or after ``E1 = min(min_y d1(y) + 1, min_z d1(z) + 2)``. (Agents that start at ``B`` or
        ``x`` are not split: their first arrival needs no entry.) ``L2`` and ``E2`` are the same
        for agent 2, ``A`` and ``B`` swapped.

        Soundness (every conflict-free solution meets a branch): suppose agent 1 is at ``B`` at
        some step up to ``U1`` and agent 2 at ``A`` at some step up to ``U2``. Their first arrivals
        ``tau1 <= U1 < E1`` and ``tau2 <= U2 < E2`` are both through the pseudo-corridor.
        Vertex case: agent 1 is at ``x`` during ``[e1, tau1 - 1]`` and agent 2 during
        ``[e2, tau2 - 1]``; if the two overlap they collide at ``x``; if agent 1 leaves first
        (``e2 >= tau1``), ``e2 = tau1`` is a swap on ``x - B`` and ``e2 = tau1 + 1`` a vertex
        conflict at ``B`` (agent 2 is there at ``e2 - 1``), so ``tau2 >= e2 + 1 >= tau1 + 3 >=
        L1 + k + 1 > U2``; symmetrically if agent 2 leaves first, ``tau1 > U1``. Swap case:
        ``tau1 = tau2`` is the swap itself, ``tau2 = tau1 + 1`` a vertex conflict at ``B`` (agent 2
        is there at ``tau2 - 1``), so one of them is at least two steps after the other and past
        its bound. Every bound used is a lower bound on the arrivals of *every* path meeting
        the agents' constraints, so no solution is lost.

        Returns ``None`` when the conflict is not of that form or the branches would not cut
        the agents' current paths (agent 1 at ``B`` and agent 2 at ``A`` at ``t + 1``).
        """
        t = c.time
        if c.kind == VERTEX:
            x = c.x1
            if t < 1 or t + 1 > m1.cost or t + 1 > m2.cost:
                return None
            lv1, lv2 = m1.levels, m2.levels
            if len(lv1[t]) != 1 or len(lv2[t]) != 1 or x not in lv1[t] or x not in lv2[t]:
                return None
            if len(lv1[t - 1]) != 1 or len(lv1[t + 1]) != 1:
                return None
            (A,), (B,) = lv1[t - 1], lv1[t + 1]
            if lv2[t - 1] != {B} or lv2[t + 1] != {A}:
                return None
            if A == B or A == x or B == x:
                return None
            inner: Tuple[int, ...] = (x,)
        elif c.kind == EDGE:
            A, B = c.x1, c.x2
            if t + 1 > m1.cost or t + 1 > m2.cost or A == B:
                return None
            if m1.levels[t] != {A} or m1.levels[t + 1] != {B} or m2.levels[t] != {B} or m2.levels[t + 1] != {A}:
                return None
            inner = ()
        else:
            return None
        k = len(inner) + 1
        starts = self.inst.starts
        if starts[i1] in inner or starts[i1] == B or starts[i2] in inner or starts[i2] == A:
            return None
        pred = self.pred

        def others(end: int, before: int) -> Tuple[List[int], List[int]]:
            """The nodes a first arrival at ``end`` not through the pseudo-corridor from
            ``before`` can come from: directly (``ys``), or through ``x`` (``zs``)."""
            if inner:
                ys = [y for y in pred[end] if y != x and y != end]
                zs = [z for z in pred[x] if z not in (x, before, end)]
            else:
                ys = [y for y in pred[end] if y != before and y != end]
                zs = []
            return ys, zs

        ys1, zs1 = others(B, A)
        ys2, zs2 = others(A, B)

        def through(lower: Callable[[int], int], near: int, far: int) -> int:
            """Lower bound on a first arrival at ``far`` through the pseudo-corridor from ``near``."""
            return max(lower(far), lower(near) + k)

        def around(lower: Callable[[int], int], ys: List[int], zs: List[int]) -> int:
            """Lower bound on any other first arrival at the far end."""
            return min([lower(y) + 1 for y in ys] + [lower(z) + 2 for z in zs] + [UNREACHABLE])

        def static(agent: int) -> Callable[[int], int]:
            dist = self.from_start(agent)
            return lambda v: int(dist[v])

        def sharp(agent: int) -> Callable[[int], int]:
            dist = self.from_start(agent)
            assert earliest is not None
            return lambda v: max(int(dist[v]), earliest(agent, v, None))

        lo1, lo2 = static(i1), static(i2)
        l1, e1 = through(lo1, A, B), around(lo1, ys1, zs1)
        l2, e2 = through(lo2, B, A), around(lo2, ys2, zs2)
        tau = t + 1  # both agents' current (first) arrivals at their far ends
        if earliest is not None:
            # sharpen the bounds that keep the split from cutting the current paths with the
            # agents' constraints (each is still a lower bound on every arrival)
            if tau > l2 + k:
                l2 = through(sharp(i2), B, A)
            if tau > e1 - 1:
                e1 = around(sharp(i1), ys1, zs1)
            if tau > l1 + k:
                l1 = through(sharp(i1), A, B)
            if tau > e2 - 1:
                e2 = around(sharp(i2), ys2, zs2)
        u1 = min(l2 + k, e1 - 1)
        u2 = min(l1 + k, e2 - 1)
        if tau > u1 or tau > u2:
            return None  # the split would not cut the current paths
        return [(i1, (RangeConstraint(i1, B, 0, u1),)), (i2, (RangeConstraint(i2, A, 0, u2),))]


class GridGeometry:
    """Coordinates of the nodes of a 4-connected grid graph, for rectangle reasoning."""

    def __init__(self, inst: MapfInstance, coords: ArrayLike):
        arr = np.asarray(coords, dtype=np.int64)
        if arr.shape != (inst.n_nodes, 2):
            raise ValueError(f"grid coordinates must have shape ({inst.n_nodes}, 2), got {arr.shape}")
        self.rows = arr[:, 0].tolist()
        self.cols = arr[:, 1].tolist()
        self.node_at: Dict[Tuple[int, int], int] = {}
        for v, (r, c) in enumerate(zip(self.rows, self.cols)):
            if (r, c) in self.node_at:
                raise ValueError(f"nodes {self.node_at[(r, c)]} and {v} share the grid cell ({r}, {c})")
            self.node_at[(r, c)] = v
        for u in range(inst.n_nodes):
            for v in inst.succ[u][1:]:
                if abs(self.rows[u] - self.rows[v]) + abs(self.cols[u] - self.cols[v]) != 1:
                    raise ValueError(f"edge {u}->{v} does not join 4-neighbouring cells: not a 4-connected grid")

    def manhattan(self, u: int, v: int) -> int:
        return abs(self.rows[u] - self.rows[v]) + abs(self.cols[u] - self.cols[v])

    def _window(self, m: MDD, v: int, t: int) -> Optional[Tuple[int, int, int, int]]:
        """Singletons ``(S, tS)`` before and ``(G, tG)`` after ``t`` with a monotone stretch between."""
        singles = m.singletons()
        before = [(ts, s) for ts, s in singles if ts <= t and self.manhattan(s, v) == t - ts]
        after = [(tg, g) for tg, g in singles if tg >= t and self.manhattan(v, g) == tg - t]
        for ts, s in before:  # earliest first
            for tg, g in reversed(after):  # latest first
                if self.manhattan(s, g) == tg - ts:
                    return s, ts, g, tg
        return None

    def split(self, c: Conflict, i1: int, m1: MDD, i2: int, m2: MDD) -> Optional[Branches]:
        """Barrier constraints for a vertex conflict of two agents crossing a rectangle, or ``None``.

        Both agents' cheapest paths pass singletons ``S_i`` (time ``tS_i``) and ``G_i``, moving
        monotonically in between, in the same row and column directions. If agent A crosses the
        rectangle ``R`` top-to-bottom and agent B left-to-right (in those directions), the
        barriers are: A not at any cell ``x`` of R's far row at ``tS_A + |x - S_A|``, and B not at
        any cell ``y`` of R's far column at ``tS_B + |y - S_B|``; only (cell, time) pairs of the
        agents' MDDs are constrained. Soundness: an agent at such an MDD pair has a path prefix
        that, completed by the MDD, is a cheapest path, so it went through its singleton ``S``
        and moved monotonically to the barrier; the two monotone stretches then cross inside R,
        and since both agents reach every cell of R at the same time (``t - r' - c'`` is
        constant along both), they collide. Both branches raise both costs (cardinal).
        """
        if c.kind != VERTEX:
            return None
        v, t = c.x1, c.time
        if t >= m1.cost or t >= m2.cost:
            return None
        w1 = self._window(m1, v, t)
        w2 = self._window(m2, v, t)
        if w1 is None or w2 is None:
            return None
        R, C = self.rows, self.cols

        def sign(x: int) -> int:
            return (x > 0) - (x < 0)

        s1, ts1, g1, _ = w1
        s2, ts2, g2, _ = w2
        dr1, dc1 = sign(R[g1] - R[s1]), sign(C[g1] - C[s1])
        dr2, dc2 = sign(R[g2] - R[s2]), sign(C[g2] - C[s2])
        if dr1 and dr2 and dr1 != dr2:
            return None
        if dc1 and dc2 and dc1 != dc2:
            return None
        dr = dr1 or dr2 or 1
        dc = dc1 or dc2 or 1
        info = {i1: (s1, ts1, g1, m1), i2: (s2, ts2, g2, m2)}
        for A, B in ((i1, i2), (i2, i1)):
            sa, tsa, ga, ma = info[A]
            sb, tsb, gb, mb = info[B]
            # transformed coordinates: both agents move towards larger r', c'
            sar, sac, gar, gac = dr * R[sa], dc * C[sa], dr * R[ga], dc * C[ga]
            sbr, sbc, gbr, gbc = dr * R[sb], dc * C[sb], dr * R[gb], dc * C[gb]
            if not (sar <= sbr and sac >= sbc and gar >= gbr and gac <= gbc):
                continue
            # rectangle rows [sbr, gbr] x cols [sac, gac] (transformed)
            if gbr - sbr + gac - sac < 1:
                return None  # a single cell: no better than the plain split
            barrier_a = []
            for cc in range(sac, gac + 1):
                x = self.node_at.get((dr * gbr, dc * cc))
                if x is None:
                    continue
                tau = tsa + self.manhattan(sa, x)
                if tau <= ma.cost and x in ma.levels[tau]:
                    barrier_a.append(VertexConstraint(A, x, tau))
            barrier_b = []
            for rr in range(sbr, gbr + 1):
                y = self.node_at.get((dr * rr, dc * gac))
                if y is None:
                    continue
                tau = tsb + self.manhattan(sb, y)
                if tau <= mb.cost and y in mb.levels[tau]:
                    barrier_b.append(VertexConstraint(B, y, tau))
            if not barrier_a or not barrier_b:
                return None
            return [(A, tuple(barrier_a)), (B, tuple(barrier_b))]
        return None
