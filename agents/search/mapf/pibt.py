"""A joint stepper in the manner of priority inheritance with backtracking (PIBT): crowds that
prioritised planning and the large-neighbourhood repair cannot untangle.

Prioritised planning (:mod:`agents.search.mapf.prioritized`) plans one agent at a time and the
repair (:mod:`agents.search.mapf.lns`) a few at a time; in a crowd where nearly every node is
near some agent, a plan needs several agents to step out of each other's way at once. This
module follows "Priority Inheritance with Backtracking for Iterative Multi-agent Path Finding"
(Okumura et al.): all agents advance together, one time step after another, and at each step the
agents decide in priority order; an agent that wants a node another agent is in the way of asks
that agent to move away first (the other agent inherits its priority for this step), and
backtracks to its next choice where the other cannot. An agent's priority grows with every step
it is away from its goal and falls back when it gets there, so an agent parked at its goal is
pushed off it by the agents that need to pass and returns later.

Occupation follows :func:`~agents.search.mapf.validate.validate`'s durative model:

- an agent at a node occupies it; an agent moving along ``u -> v`` (``d`` steps) occupies both
  ``u`` and ``v`` for all ``d`` steps, then ``v`` alone;
- two agents conflict when a node one occupies is a node the other occupies or is near it
  (proximity); after its final arrival an agent stays at its goal.

So a node ``v`` is open to an agent at ``u`` at a step when no node at or near ``v`` is occupied
by another agent. Nothing is set free within a step (an agent that starts to move keeps its node
until it arrives), so, unlike classic PIBT, where the pushed agent and the pusher move in the
same step, here the pushed agent starts to move away and the pusher waits, keeping the nodes at
and near the node it wants *claimed* for the rest of the step (no lower-priority agent may move
there), until the node is open. An agent that is pushed first looks for an open node out of the
claimed ones to move to at once; if there is none, it pushes in its turn. Every move starts only
to an open node, so every step's occupation is free of conflicts, and the plan is valid by
construction (under unit time it is conservative: the edge's far end is occupied during its one
step too).

Three more rules make it work on the planner's graphs:

- an agent whose goal has no way out (no edge leaves it: the goals attached to the buffer graph)
  stays there for good once it arrives, and the nodes at and near its goal are closed to everybody
  else; it may arrive only where every other agent not parked yet can still reach its goal
  through the nodes left open, else it waits at the lowest priority so that the others push it
  aside; an agent about to wait recomputes its distances around the nodes closed since it last
  did;
- an agent that has not come closer to its goal for ``patience`` steps takes a move that is as
  good as waiting instead of waiting (two agents waiting for each other would otherwise stay);
- a run in which no new high of agents at their goals is reached for ``stall_moves`` moves of
  the longest edge is given up and the stepping starts again from the starts with other
  tie-breaks, up to ``restarts`` times.

The stepper is incomplete all the same: it can fail where a plan exists (status ``"timeout"``).
Its budget is counted in work, the candidate moves examined over all runs (``expansion_limit``),
and ties are broken by a generator seeded by ``seed``, so a solve is a function of the instance,
the options and the seed; ``time_limit`` is only a safety net.
"""
from __future__ import annotations

import random
import sys
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np
from scipy.sparse.csgraph import breadth_first_order, connected_components, dijkstra

from .instance import UNREACHABLE, MapfInstance
from .prioritized import SolveRun, check_common_options, no_plan_reason, plan_result
from .result import MapfResult
from .sipp import BudgetExceeded, Events
from .solver import DEFAULT_JOINT_CHECK_STATES

__all__ = ["DEFAULT_PIBT_EXPANSION_LIMIT", "StepperStats", "solve_pibt"]

#: default candidate moves examined over one solve
DEFAULT_PIBT_EXPANSION_LIMIT = 5_000_000
#: default ``patience``: steps without getting closer to its goal after which an agent takes a
#: move as good as waiting rather than wait
DEFAULT_PATIENCE = 5
#: default ``stall_moves``: moves of the longest edge without a new high of agents at their
#: goals after which a run is given up (100 on the 1000-node buffer graph: 700 steps, where the
#: runs that succeed go at most 115 steps without one)
DEFAULT_STALL_MOVES = 100
#: default ``restarts``
DEFAULT_RESTARTS = 20


@dataclass
class StepperStats:
    """Statistics of one priority inheritance stepper solve (its work and seconds are the result's)."""

    #: time steps of the last run
    steps: int = 0
    #: runs started again from the starts
    restarts: int = 0
    #: moves started in the last run
    moves: int = 0


class _Stepper:
    """The joint state of all agents and one PIBT step over it."""

    def __init__(self, inst: MapfInstance, seed: int, run: SolveRun, patience: int = DEFAULT_PATIENCE) -> None:
        self.inst = inst
        self.run = run
        n, k = inst.n_nodes, inst.n_agents
        near = inst.near
        self.zone: List[List[int]] = [[x] + near[x] for x in range(n)] if near is not None else [[x] for x in range(n)]
        self.near_set: List[frozenset] = ([frozenset(near[x]) for x in range(n)] if near is not None
                                          else [frozenset()] * n)
        rng = random.Random(seed)
        #: a fixed tie-break value per node, between equally good moves (drawn once)
        self.tie = [rng.random() for _ in range(n)]
        #: the fractional part of every agent's priority: ties between agents
        self.eps = [rng.random() for _ in range(k)]
        self.prio = list(self.eps)
        self.holder = [-1] * n  # the agent occupying each node (at most one)
        self.count = [0] * n  # occupied nodes at or near each node
        self.claim_owner = [-1] * n
        self.claim_step = [-1] * n
        self.decided = [-1] * k
        self.failed = [-1] * k  # the step at which an agent pushed off its node could not leave
        self.pos = list(inst.starts)
        self.target = [-1] * k  # where a moving agent goes (-1: at its node)
        self.arrival = [0] * k
        self.events: List[Events] = [[(s, 0)] for s in inst.starts]
        #: per agent, its candidates at each node (for its current distances)
        self.cands: List[Dict[int, List[Tuple[int, int, int]]]] = [{} for _ in range(k)]
        self.step = 0
        self.moves = 0
        # An agent whose goal has no way out stays there for good once it arrives: the nodes at
        # and near that goal are closed to everybody else from then on.
        self.final = [len(inst.succ_d[g]) == 1 for g in inst.goals]
        self.parked = [False] * k
        self.closed = np.zeros(n, dtype=bool)
        self.version = 0  # how many times nodes were closed
        self.edges = inst.durations.tocsr()
        self.reverse = self.edges.T.tocsr()
        self.reverse_rows = np.repeat(np.arange(n), np.diff(self.reverse.indptr))
        self.reduced = self.reverse
        self.reverse_version = 0
        self.h: List[List[int]] = list(inst.h)
        self.h_version = [0] * k
        #: per agent, (closing version, step // 8) of its last refused arrival at its final goal: it
        #: asks again 8 steps later at the latest, or as soon as more nodes are closed
        self.refused: List[Tuple[int, int]] = [(-1, -1)] * k
        self.patience = patience
        #: per agent, the least distance to its goal so far and the step it got there
        self.best = [inst.h[a][s] for a, s in enumerate(inst.starts)]
        self.progress = [0] * k
        self.parking_checks = 0
        self.replans = 0

    # ------------------------------------------------------------------ occupation
    def occupy(self, a: int, x: int) -> None:
        self.holder[x] = a
        count = self.count
        for y in self.zone[x]:
            count[y] += 1

    def vacate(self, x: int) -> None:
        self.holder[x] = -1
        count = self.count
        for y in self.zone[x]:
            count[y] -= 1

    def candidates(self, a: int, u: int) -> List[Tuple[int, int, int]]:
        """``(rank key, node, duration)`` for ``a`` at ``u``: its moves, best first by the steps
        to its goal through them, and waiting (key: one step more than the distance from ``u``)."""
        mine = self.cands[a]
        c = mine.get(u)
        if c is None:
            h = self.h[a]
            unit = self.inst.unit
            tie = self.tie
            closed = self.closed
            opts = [(h[u] + 1, u, 1)]
            for v, d in self.inst.succ_d[u][1:]:
                if h[v] < UNREACHABLE and not closed[v]:
                    d = 1 if unit else d
                    opts.append((d + h[v], v, d))
            opts.sort(key=lambda o: (o[0], o[1] != u, tie[o[1]]))
            c = opts
            mine[u] = c
        return c

    # ------------------------------------------------------------------ final goals
    def refresh(self, a: int) -> bool:
        """Recompute ``a``'s distances around the closed nodes if some were closed since it last
        did; ``True`` if they changed."""
        if self.h_version[a] == self.version:
            return False
        self.h_version[a] = self.version
        if self.reverse_version != self.version:  # the reversed graph without the closed nodes
            keep = ~self.closed
            m = self.reverse.copy()
            m.data[~(keep[self.reverse_rows] & keep[m.indices])] = 0
            m.eliminate_zeros()  # (an explicit zero would be an edge of length 0)
            self.reduced = m
            self.reverse_version = self.version
        dist = dijkstra(self.reduced, directed=True, indices=[self.inst.goals[a]], unweighted=self.inst.unit)[0]
        self.h[a] = np.where(np.isfinite(dist), dist, UNREACHABLE).astype(np.int64).tolist()
        self.cands[a] = {}
        self.replans += 1
        self.best[a] = self.h[a][self.pos[a]]
        self.progress[a] = self.step
        return True

    def may_park(self, a: int) -> bool:
        """Whether ``a`` may arrive at its final goal for good: every other agent not parked can
        still reach its goal (along the graph's edges) with the nodes at and near that goal closed."""
        step = self.step
        if self.refused[a] == (self.version, step // 8):
            return False  # refused at this version recently: ask again a few steps later
        self.parking_checks += 1
        goals = self.inst.goals
        keep = ~self.closed
        keep[self.zone[goals[a]]] = False
        idx = np.flatnonzero(keep)
        inv = np.full(len(keep), -1, dtype=np.int64)
        inv[idx] = np.arange(len(idx))
        sub = self.edges[idx][:, idx].tocsr()
        _, labels = connected_components(sub, directed=True, connection="strong")
        big = labels == np.bincount(labels).argmax()
        others = [b for b in range(len(goals)) if b != a and not self.parked[b]]
        if not others:
            return True
        src = inv[[self.target[b] if self.target[b] >= 0 else self.pos[b] for b in others]]
        dst = inv[[goals[b] for b in others]]
        if (src < 0).any() or (dst < 0).any():
            self.refused[a] = (self.version, step // 8)
            return False
        bigf = big.astype(np.float64)
        out_ok = big[src] | (sub[src] @ bigf > 0)
        in_ok = big[dst] | (sub.T.tocsr()[dst] @ bigf > 0)
        for j in np.flatnonzero(~(out_ok & in_ok)):
            seen = breadth_first_order(sub, int(src[j]), directed=True, return_predecessors=False)
            if not (seen == dst[j]).any():
                self.refused[a] = (self.version, step // 8)
                return False
        return True

    def park(self, a: int) -> None:
        """``a`` has arrived at its final goal for good: close the nodes at and near it."""
        self.parked[a] = True
        self.closed[self.zone[self.inst.goals[a]]] = True
        self.version += 1

    # ------------------------------------------------------------------ claims of one step
    def claimed_by_other(self, x: int, a: int) -> bool:
        return self.claim_step[x] == self.step and self.claim_owner[x] != a

    def claim(self, a: int, v: int) -> List[int]:
        """Claim the nodes at and near ``v`` for ``a`` (those nobody claimed yet this step)."""
        got = []
        step = self.step
        for y in self.zone[v]:
            if self.claim_step[y] != step:
                self.claim_step[y] = step
                self.claim_owner[y] = a
                got.append(y)
        return got

    def unclaim(self, nodes: List[int]) -> None:
        for y in nodes:
            self.claim_step[y] = -1

    def is_open(self, a: int, u: int, v: int) -> bool:
        """Whether no other agent occupies a node at or near ``v`` (``a`` is at ``u``)."""
        own = 1 if v in self.near_set[u] else 0
        return self.count[v] == own

    def start_move(self, a: int, v: int, d: int) -> None:
        self.target[a] = v
        self.arrival[a] = self.step + d
        self.occupy(a, v)
        self.moves += 1

    # ------------------------------------------------------------------ one agent's decision
    def can_enter(self, a: int, u: int, v: int) -> bool:
        """Whether ``a`` at ``u`` may start to move to ``v`` now: ``v`` is open, not claimed by
        another agent, and, if it is ``a``'s final goal, nobody else needs the nodes around it."""
        if self.claimed_by_other(v, a) or not self.is_open(a, u, v):
            return False
        return not (v == self.inst.goals[a] and self.final[a] and not self.may_park(a))

    def push(self, a: int, v: int) -> bool:
        """``a`` wants ``v``, where other agents are in the way: claim the nodes at and near ``v``
        and push the agents at them that are not moving (each must move off in its turn).
        ``True`` if every one of them can; ``a`` then waits until ``v`` is open."""
        blockers: List[int] = []
        step = self.step
        for y in self.zone[v]:
            b = self.holder[y]
            if b < 0 or b == a or b in blockers or self.target[b] >= 0:
                continue  # nobody, or moving: it will leave (or be pushed when it arrives)
            if self.decided[b] == step:
                return False  # it has decided to stay this step
            blockers.append(b)
        mine = self.claim(a, v)
        for b in blockers:
            if self.decided[b] == step:  # decided in the meantime, pushed by another agent
                ok = self.failed[b] != step
            else:
                ok = self.pibt(b)
            if not ok:
                self.unclaim(mine)
                return False
        return True

    def pibt(self, a: int) -> bool:
        """Decide ``a``'s action at this step: move to an open node, wait, or wait while the agents
        in the way of the node it wants move off (pushed in their turn). Candidates are taken
        best first; among equally good ones, open nodes before nodes that need a push.
        ``False``: ``a`` was pushed off its node and can do none of this."""
        self.decided[a] = self.step
        u = self.pos[a]
        pushed = self.claimed_by_other(u, a)
        # no progress for a while: waiting comes last, after every move and push
        restless = not pushed and self.step - self.progress[a] >= self.patience and u != self.inst.goals[a]
        counter = self.run.counter
        cands = self.candidates(a, u)
        if pushed:  # first any open node out of the claimed ones, at once
            for _, v, d in cands:
                counter[0] += 1
                if v != u and self.can_enter(a, u, v):
                    self.start_move(a, v, d)
                    return True
        i, m = 0, len(cands)
        while i < m:
            j = i + 1
            while j < m and cands[j][0] == cands[i][0]:
                j += 1
            group = cands[i:j]
            i = j
            stay = False
            for _, v, d in group:
                counter[0] += 1
                if v == u:
                    if pushed:
                        continue
                    if not restless:  # waiting first among equals
                        if self.refresh(a):  # nodes were closed since: look again with the new distances
                            return self.pibt(a)
                        return True
                    stay = True
                elif not pushed and self.can_enter(a, u, v):
                    self.start_move(a, v, d)
                    return True
            if stay:  # waiting is better than what is left (and as good as the pushes left)
                if self.refresh(a):  # nodes were closed since: look again with the new distances
                    return self.pibt(a)
                return True
            for _, v, _d in group:
                counter[0] += 1
                if v != u and not self.claimed_by_other(v, a) and not self.is_open(a, u, v) and self.push(a, v):
                    return True  # wait here until v is open
        self.failed[a] = self.step
        return False

    # ------------------------------------------------------------------ the joint step
    def advance(self) -> bool:
        """One time step of every agent; ``True`` once every agent is at its goal and not moving."""
        step = self.step
        goals = self.inst.goals
        pos, target, events = self.pos, self.target, self.events
        for a in range(len(pos)):
            if target[a] >= 0 and self.arrival[a] == step:
                self.vacate(pos[a])
                pos[a] = target[a]
                target[a] = -1
                events[a].append((pos[a], step))
                if self.final[a] and pos[a] == goals[a]:
                    self.park(a)
        if all(target[a] < 0 and pos[a] == goals[a] for a in range(len(pos))):
            return True
        prio, eps = self.prio, self.eps
        free = []
        parked = self.parked
        for a in range(len(pos)):
            if parked[a]:
                continue
            if target[a] < 0:
                dist = self.h[a][pos[a]]
                if dist < self.best[a] or dist == 0:
                    self.best[a] = dist
                    self.progress[a] = step
                if pos[a] == goals[a] or self.refused[a][0] == self.version:
                    prio[a] = eps[a]
                else:
                    prio[a] += 1.0
                free.append(a)
            else:
                prio[a] += 1.0
        free.sort(key=lambda a: -prio[a])
        for a in free:
            if self.decided[a] != step:
                self.pibt(a)
        for a in free:
            if target[a] < 0:
                events[a].append((pos[a], step + 1))
        self.step += 1
        return False

    def paths(self) -> List[Events]:
        """Each agent's events up to its final arrival (the trailing wait at its goal dropped)."""
        out = []
        for ev in self.events:
            ev = list(ev)
            while len(ev) >= 2 and ev[-1][0] == ev[-2][0]:
                ev.pop()
            out.append(ev)
        return out


def _overlap(inst: MapfInstance, nodes: Tuple[int, ...], what: str) -> Optional[str]:
    """Why agents at ``nodes`` (starts or goals) conflict among themselves, if they do."""
    if inst.near is None:
        return None
    idx = {v: i for i, v in enumerate(nodes)}
    for i, v in enumerate(nodes):
        for w in inst.near[v]:
            j = idx.get(w)
            if j is not None and j > i:
                return f"the {what}s of agents {i} and {j} are within the proximity radius of each other"
    return None


def solve_pibt(inst: MapfInstance, *, expansion_limit: Optional[int] = DEFAULT_PIBT_EXPANSION_LIMIT,
               time_limit: Optional[float] = None, seed: int = 0, patience: int = DEFAULT_PATIENCE,
               stall_moves: int = DEFAULT_STALL_MOVES, restarts: int = DEFAULT_RESTARTS,
               joint_check_states: int = DEFAULT_JOINT_CHECK_STATES) -> MapfResult:
    """Step all agents together by priority inheritance with backtracking; a
    :class:`~agents.search.mapf.result.MapfResult` (``solver`` ``"pibt"``, ``work``: candidate moves
    examined, ``stats``: a :class:`StepperStats`; its lower bound is the sum of the agents' distances).

    Args:
        inst: the instance (either time model, with or without proximity).
        expansion_limit: candidate moves examined over the whole solve, restarts included
            (``None``: no limit); reaching it ends the solve with status ``"timeout"``. Every
            step examines at least one, so it also bounds the makespan.
        time_limit: wall-clock seconds, a safety net (``None``: none).
        seed: seeds the tie-breaks (between agents of equal priority and between equally good
            moves) and those of the restarts; the same seed, the same plan.
        patience: steps without getting closer to its goal after which an agent moves rather
            than waits where a move is as good as waiting (0: always).
        stall_moves: a run in which the number of agents at their goals has not reached a new
            high for this many moves of the graph's longest edge (in steps: ``stall_moves`` x
            the longest duration) is given up and the stepping starts again from the starts with
            other tie-breaks.
        restarts: how many times the stepping may start again.
        joint_check_states: as for :func:`~agents.search.mapf.prioritized.solve_prioritized`: a
            small impossible part of the instance is reported ``"infeasible"`` before stepping.

    Returns:
        status ``"suboptimal"`` (or ``"optimal"`` where the sum of costs equals the lower bound)
        with conflict-free paths, ``"timeout"`` (the message says which limit and how many agents
        were at their goals), or ``"infeasible"`` when some agent's goal cannot be reached from
        its start even alone, two starts or two goals are within the proximity radius of each
        other, or the joint check proves that no plan exists.
    """
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    for name, value in (("patience", patience), ("restarts", restarts)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    if isinstance(stall_moves, bool) or not isinstance(stall_moves, int) or stall_moves < 1:
        raise ValueError(f"stall_moves must be an integer >= 1, got {stall_moves!r}")
    check_common_options(expansion_limit, time_limit, joint_check_states)
    run = SolveRun(expansion_limit, time_limit, "pibt", StepperStats())
    k = inst.n_agents
    reason = (_overlap(inst, inst.starts, "start") or _overlap(inst, inst.goals, "goal")
              or no_plan_reason(inst, joint_check_states))
    if reason is not None:
        return run.finish(inst, MapfResult("infeasible", message=reason))
    lb = sum(inst.h[i][inst.starts[i]] for i in range(k))
    stall = stall_moves * (1 if inst.unit else inst.max_duration)
    seeds = random.Random(seed)
    limit = sys.getrecursionlimit()
    if limit < 4 * k + 100:
        sys.setrecursionlimit(4 * k + 100)
    attempt = 0
    goals = inst.goals

    def counted(st: _Stepper) -> None:
        run.stats.steps, run.stats.restarts, run.stats.moves = st.step, attempt, st.moves

    try:
        while True:
            st = _Stepper(inst, seed if attempt == 0 else seeds.getrandbits(32), run, patience)
            for a, s in enumerate(inst.starts):
                st.occupy(a, s)
            best, since = -1, 0
            while not st.advance():
                run.check_limits()
                home = sum(1 for a in range(k) if st.target[a] < 0 and st.pos[a] == goals[a])
                if home > best:
                    best, since = home, st.step
                elif st.step - since > stall:
                    break
            else:
                break  # every agent at its goal
            if attempt == restarts:
                counted(st)
                return run.finish(inst, MapfResult("timeout", lower_bound=lb, message=(
                    f"priority inheritance stepper: {attempt + 1} runs stalled (the last with {best} of {k} "
                    f"agents at their goals, none more for {stall} steps)")))
            attempt += 1
    except (BudgetExceeded, TimeoutError) as exc:
        home = sum(1 for a in range(k) if st.target[a] < 0 and st.pos[a] == goals[a])
        which = (f"expansion limit of {expansion_limit}" if isinstance(exc, BudgetExceeded)
                 else f"time limit of {time_limit:g} s")
        counted(st)
        return run.finish(inst, MapfResult("timeout", lower_bound=lb, message=(
            f"{which} reached (priority inheritance stepper, run {attempt + 1}, step {st.step}; "
            f"{home} of {k} agents at their goals)")))
    finally:
        sys.setrecursionlimit(limit)
    counted(st)
    return run.finish(inst, plan_result(st.paths(), lb, (
        f"priority inheritance stepper: {st.step} steps, {st.moves} moves, {attempt} restarts; cost not bounded")))
