"""Prioritised planning (PP) with safe-interval path planning: many agents, fast, not optimal.

Agents are planned one at a time in a priority order; each gets its earliest path that avoids
every path planned before it (:func:`~agents.search.mapf.sipp.sipp`), then its path is
reserved (:class:`~agents.search.mapf.sipp.IntervalTable`). The agents not planned yet wait
at their starts, so their starts are kept free too (held) until they are planned. The first
order releases a crowd from its edge inwards (:func:`release_order`: an agent comes after the
agents whose starts shut it in or lie at its goal); an agent shut in by waiting agents all the
same is planned after them (:func:`plan_in_order`). Prioritised planning is incomplete: an
agent may still find no path because earlier agents block it. When that happens planning
starts again in the far-first order (:func:`initial_order`), then with the failed agent moved
to the front, up to ``restarts`` times; an agent that fails although it was first in the order
ends planning at once, since planning is deterministic and the restart would repeat the
attempt.
The order is a function of the instance alone, so the same instance gives the same plan on any
machine.

The budget is counted in work: SIPP expansions over all agents and restarts
(``expansion_limit``); the wall-clock ``time_limit`` is only a safety net. Reaching either
returns status ``"timeout"`` (the message says which). Prioritised planning proves nothing
where it fails, so a small impossible part of the instance is first looked for by the
exhaustive joint check, as CBS does (``joint_check_states``).
"""
from __future__ import annotations

import collections
import heapq
import time as _time
from dataclasses import dataclass
from typing import Dict, Generic, List, Optional, Sequence, Set, Tuple, TypeVar

import numpy as np
from scipy.sparse.csgraph import breadth_first_order

from . import compiled
from .conflict_table import ConflictTable, soft_sipp
from .feasibility import infeasible_component
from .instance import UNREACHABLE, MapfInstance
from .result import MapfResult
from .sipp import FOREVER, BudgetExceeded, Events, interval_table, sipp
from .solver import DEFAULT_JOINT_CHECK_STATES

#: default SIPP expansions of one solve, over all agents and restarts
DEFAULT_EXPANSION_LIMIT = 2_000_000
#: how many times prioritised planning puts an agent shut in by waiting agents back behind
#: them (:func:`plan_in_order`'s ``deferrals``)
DEFAULT_DEFERRALS = 3
#: default ``start_hold``, in moves of the graph's mean duration (30 steps on the 1000-node
#: buffer graph, whose edges take 5 steps on average; 6 on a unit-time grid)
DEFAULT_START_HOLD_MOVES = 6


@dataclass
class PrioritizedStats:
    """Statistics of one prioritised planning solve (its work and seconds are the result's)."""

    #: priority orders planned (the first one and each restart)
    orders: int = 0


S = TypeVar("S")


class SolveRun(Generic[S]):
    """The counters and limits of one solve: expansions so far, the expansion budget, the deadline.

    Args:
        expansion_limit: expansions over the whole solve (``None``: no limit).
        time_limit: wall-clock seconds from now, a safety net (``None``: none).
        solver: the solver's name, which its results carry.
        stats: the solver's own statistics, filled as it goes and attached to its result.
    """

    def __init__(self, expansion_limit: Optional[int], time_limit: Optional[float], solver: str, stats: S) -> None:
        self.t0 = _time.perf_counter()
        #: expansions so far (a one-element list, shared with the low-level searches)
        self.counter = [0]
        self.budget = expansion_limit
        #: ``time.perf_counter()`` past which the solve stops (``None``: never)
        self.deadline = None if time_limit is None else self.t0 + time_limit
        self.solver = solver
        self.stats = stats

    def check_limits(self) -> None:
        """Raise ``TimeoutError`` past the deadline, :class:`~agents.search.mapf.sipp.BudgetExceeded`
        past the expansion budget."""
        if self.deadline is not None and _time.perf_counter() > self.deadline:
            raise TimeoutError
        if self.budget is not None and self.counter[0] > self.budget:
            raise BudgetExceeded

    def finish(self, inst: MapfInstance, res: MapfResult) -> MapfResult:
        """``res`` with this run's work (expansions), seconds, solver name, statistics and the
        instance's time model."""
        res.work = self.counter[0]
        res.runtime_s = _time.perf_counter() - self.t0
        res.solver = self.solver
        res.stats = self.stats
        res.time_model = inst.time_model
        return res


def check_common_options(expansion_limit: Optional[int], time_limit: Optional[float],
                         joint_check_states: int) -> None:
    """Refuse bad values of the options every prioritised or repair solve takes (``ValueError``)."""
    if expansion_limit is not None and expansion_limit < 1:
        raise ValueError(f"expansion_limit must be >= 1 or None, got {expansion_limit!r}")
    if time_limit is not None and not time_limit > 0:
        raise ValueError(f"time_limit must be > 0 seconds or None, got {time_limit!r}")
    if joint_check_states < 0:
        raise ValueError(f"joint_check_states must be >= 0, got {joint_check_states!r}")


def default_start_hold(inst: MapfInstance) -> int:
    """``DEFAULT_START_HOLD_MOVES`` moves of the graph's mean duration, in steps."""
    data = inst.durations.data
    return int(round(DEFAULT_START_HOLD_MOVES * (float(data.mean()) if len(data) else 1.0)))


def no_plan_reason(inst: MapfInstance, joint_check_states: int) -> Optional[str]:
    """Why no plan exists, if that is quick to prove: an agent that cannot reach its goal even
    alone, or a small connected part of the graph whose agents have no joint plan (searched
    exhaustively where it has at most ``joint_check_states`` joint configurations; 0: not
    searched). ``None``: no proof found (a plan may or may not exist)."""
    for i in range(inst.n_agents):
        if inst.h_array[i, inst.starts[i]] >= UNREACHABLE:
            return f"agent {i} cannot reach its goal from its start"
    if joint_check_states > 0:
        return infeasible_component(inst, joint_check_states)
    return None


def plan_result(paths: List[Events], lower_bound: int, message: str) -> MapfResult:
    """The result of a conflict-free plan: status ``"optimal"`` where its sum of costs equals
    ``lower_bound`` (then the message says so), else ``"suboptimal"`` with ``message``."""
    costs = [p[-1][1] for p in paths]
    soc = sum(costs)
    status = "optimal" if soc == lower_bound else "suboptimal"
    msg = "cost equals the lower bound" if status == "optimal" else message
    return MapfResult(status, paths, soc, max(costs, default=0), lower_bound, message=msg)


def start_blockers(inst: MapfInstance) -> List[List[int]]:
    """Per agent ``i``, the other agents ``j`` (ascending) whose start an agent parked at ``i``'s
    goal would block: the start is the goal or near it (from the near lists, not all pairs)."""
    at: Dict[int, int] = {s: j for j, s in enumerate(inst.starts)}
    near = inst.near
    out: List[List[int]] = []
    for i, g in enumerate(inst.goals):
        nodes = [g] + (near[g] if near is not None else [])
        out.append(sorted(j for j in (at.get(x) for x in nodes) if j is not None and j != i))
    return out


def initial_order(inst: MapfInstance) -> List[int]:
    """Far agents first (decreasing distance to the goal, ties by index: a long path is the
    hardest to fit among others), except that an agent whose goal is at or near another
    agent's start comes after that agent (it could not park before the other has left).
    Agents on a cycle of such precedences keep the far-first order among themselves, last."""
    k = inst.n_agents
    to_go = inst.h_array[np.arange(k), list(inst.starts)].tolist() if k else []
    rank = sorted(range(k), key=lambda i: (-to_go[i], i))
    pos = {a: r for r, a in enumerate(rank)}
    after: List[List[int]] = [[] for _ in range(k)]
    waiting = [0] * k
    for i, blocked in enumerate(start_blockers(inst)):
        for j in blocked:
            after[j].append(i)  # i parks where j waits: j goes first
            waiting[i] += 1
    ready = [(pos[i], i) for i in range(k) if not waiting[i]]
    heapq.heapify(ready)
    order: List[int] = []
    while ready:
        _, j = heapq.heappop(ready)
        order.append(j)
        for i in after[j]:
            waiting[i] -= 1
            if not waiting[i]:
                heapq.heappush(ready, (pos[i], i))
    placed = set(order)
    return order + [i for i in rank if i not in placed]


def release_order(inst: MapfInstance) -> List[int]:
    """The first priority order of :func:`solve_prioritized`: agents released in rounds, each
    after the agents whose starts shut it in.

    An agent not planned yet waits at its start (:func:`plan_in_order`), so its start and the
    nodes near it are closed to the agents planned before it. An agent is released once it can
    reach its goal (following the graph's directed edges) through nodes at or near no start of
    an agent not released yet (its own start apart), and once its start and its goal are at or
    near no such start; the agents released in a round follow :func:`initial_order` among themselves, and
    the agents never released come last, in that order too. Paths of the agents planned before
    are not looked at (prioritised planning deals with them), so the order is cheap: one
    breadth-first search per agent and round over the nodes left open.
    """
    k, n = inst.n_agents, inst.n_nodes
    base = initial_order(inst)
    pos = {a: r for r, a in enumerate(base)}
    near = inst.near
    starts, goals = inst.starts, inst.goals
    reach = [[starts[a]] + (list(near[starts[a]]) if near is not None else []) for a in range(k)]
    cover = np.zeros(n, dtype=np.int64)  # how many unreleased agents' starts each node is at or near
    for a in range(k):
        cover[reach[a]] += 1
    edges = inst.durations.tocsr()
    fast = inst.moves_csr if compiled.active() else None  # the same test, compiled
    left = set(range(k))
    order: List[int] = []
    while left:
        ready = []
        for a in sorted(left, key=pos.__getitem__):
            open_ = cover == 0
            own = np.array(reach[a])
            open_[own[cover[own] == 1]] = True  # near a's own start only
            g = goals[a]
            if not (open_[g] and open_[starts[a]]):
                continue  # the goal or the start is at or near the start of an agent still waiting
            if fast is not None:
                if compiled.reaches(fast[0], fast[1], open_, starts[a], g):
                    ready.append(a)
                continue
            idx = np.flatnonzero(open_)
            sub = np.full(n, -1, dtype=np.int64)
            sub[idx] = np.arange(len(idx))
            seen = breadth_first_order(edges[idx][:, idx], int(sub[starts[a]]), directed=True,
                                       return_predecessors=False)
            if (seen == sub[g]).any():
                ready.append(a)
        if not ready:
            break
        for a in ready:
            left.discard(a)
            cover[reach[a]] -= 1
            order.append(a)
    return order + [a for a in base if a in left]


def plan_in_order(inst: MapfInstance, order: Sequence[int], counter: List[int],
                  budget: Optional[int] = None, deadline: Optional[float] = None,
                  start_hold: int = 0, soft: Optional[ConflictTable] = None,
                  soft_limit: Optional[int] = None,
                  deferrals: int = 1) -> Tuple[Optional[List[Optional[Events]]], Optional[int]]:
    """Plan agents in ``order``; returns ``(paths, None)`` or ``(None, failed agent)``.

    ``paths[i]`` is agent ``i``'s events. An agent not planned yet waits at its start, so its
    start (and the nodes near it) is held for it: earlier agents keep away from it until it is
    planned (without this, on a dense buffer graph most later agents find their start passed by
    in the first steps, before they can get away). Only an agent that must park at or near a
    held start sees that hold end after ``start_hold`` steps (the waiting agent then has to be
    gone by the time it arrives). An agent that finds no path while shut in by agents still
    waiting at their starts is put back behind them, at most ``deferrals`` times. Raises
    :class:`~agents.search.mapf.sipp.BudgetExceeded` past ``budget`` expansions and
    ``TimeoutError`` past ``deadline`` (``time.perf_counter()``).

    With ``soft`` (an empty :class:`~agents.search.mapf.conflict_table.ConflictTable` of the
    instance) no agent fails: one that finds no conflict-free path gets a path with few conflicts
    with the paths planned so far and the starts of the agents still waiting
    (:func:`~agents.search.mapf.conflict_table.soft_sipp`, at most ``soft_limit`` expansions; an agent
    whose search passes that limit is reported as failed), and the later agents plan around
    it as around any other. ``soft`` then holds every agent's path.
    """
    if isinstance(deferrals, bool) or not isinstance(deferrals, int) or deferrals < 0:
        raise ValueError(f"deferrals must be an integer >= 0, got {deferrals!r}")
    table = interval_table(inst)
    paths: List[Optional[Events]] = [None] * inst.n_agents
    for i in order:
        table.hold(i, inst.starts[i], FOREVER)
        if soft is not None:
            soft.hold(i, inst.starts[i], FOREVER)
    unplanned = set(order)
    blockers = start_blockers(inst)
    queue = collections.deque(order)
    deferred: Dict[int, int] = {}  # agent -> times put back
    while queue:
        if deadline is not None and _time.perf_counter() > deadline:
            raise TimeoutError
        i = queue.popleft()
        table.release(i)
        unplanned.discard(i)
        shortened = [j for j in blockers[i] if j in unplanned]
        for j in shortened:
            table.release(j)
            table.hold(j, inst.starts[j], start_hold)
        explored: Set[int] = set()
        p = sipp(inst, i, table, budget, counter, explored)
        for j in shortened:  # for everybody else, the hold lasts until j is planned
            table.release(j)
            table.hold(j, inst.starts[j], FOREVER)
        if p is not None:
            paths[i] = p
            table.reserve(i, p)
            if soft is not None:
                soft.release(i)
                soft.reserve(i, p)
            continue
        # shut in by agents still waiting at their starts? plan them first, then try again
        region = set(explored)
        region.add(inst.starts[i])
        for u in explored:
            region.update(inst.succ[u])
        waiting: Set[int] = set()
        for x in region:
            waiting |= table.holders(x)
        if deferred.get(i, 0) >= deferrals or not waiting:
            if soft is None:
                return None, i
            soft.release(i)
            p = soft_sipp(inst, i, soft, budget, counter, soft_limit)
            if p is None:
                return None, i
            paths[i] = p
            table.reserve(i, p)
            soft.reserve(i, p)
            continue
        deferred[i] = deferred.get(i, 0) + 1
        table.hold(i, inst.starts[i], FOREVER)
        unplanned.add(i)
        ahead = [a for a in queue if a in waiting]
        for a in ahead:
            queue.remove(a)
        queue.appendleft(i)
        queue.extendleft(reversed(ahead))
    return paths, None


def solve_prioritized(inst: MapfInstance, *, restarts: int = 20,
                      expansion_limit: Optional[int] = DEFAULT_EXPANSION_LIMIT,
                      time_limit: Optional[float] = None,
                      order: Optional[Sequence[int]] = None,
                      start_hold: Optional[int] = None,
                      joint_check_states: int = DEFAULT_JOINT_CHECK_STATES) -> MapfResult:
    """Prioritised planning with SIPP and priority restarts; a :class:`~agents.search.mapf.result.MapfResult`
    (``solver`` ``"prioritized"``, ``work``: SIPP expansions, ``stats``: a :class:`PrioritizedStats`).

    Args:
        inst: the instance (either time model, with or without proximity).
        restarts: how many times planning may be redone after an agent fails: first (without
            ``order``) in :func:`initial_order` where :func:`release_order` failed, then with
            the failed agent moved to the front (never for an agent already at the front: that
            attempt would be repeated exactly).
        expansion_limit: SIPP expansions over the whole solve (``None``: no limit).
        time_limit: wall-clock seconds, a safety net (``None``: none).
        order: the first priority order (default :func:`release_order`, then
            :func:`initial_order` if that fails).
        start_hold: steps ``0 .. start_hold`` for which an agent not planned yet keeps its start
            against an agent that must park at or near it (see :func:`plan_in_order`); default
            ``DEFAULT_START_HOLD_MOVES`` moves of the graph's mean duration.
        joint_check_states: before planning, each connected part of the graph whose agents'
            joint configurations number at most this many is searched exhaustively
            (:func:`~agents.search.mapf.feasibility.infeasible_component`), as CBS does, so
            that an impossible small part is reported ``infeasible`` at once instead of
            spending the budget (0: no check).

    Returns:
        status ``"suboptimal"`` with paths (their sum of costs is not bounded), ``"timeout"``
        (budget, time or restarts used up; the message says which), or ``"infeasible"`` when
        some agent's goal cannot be reached from its start even alone, or the joint check
        proves that no plan exists.
    """
    if start_hold is None:
        start_hold = default_start_hold(inst)
    if start_hold < 0:
        raise ValueError(f"start_hold must be >= 0, got {start_hold!r}")
    if restarts < 0:
        raise ValueError(f"restarts must be >= 0, got {restarts!r}")
    check_common_options(expansion_limit, time_limit, joint_check_states)
    run = SolveRun(expansion_limit, time_limit, "prioritized", PrioritizedStats())
    stats = run.stats
    k = inst.n_agents

    def finish(res: MapfResult) -> MapfResult:
        return run.finish(inst, res)

    reason = no_plan_reason(inst, joint_check_states)
    if reason is not None:
        return finish(MapfResult("infeasible", message=reason))
    if order is not None:
        cur = list(order)
        if sorted(cur) != list(range(k)):
            raise ValueError(f"order must be a permutation of the {k} agents")
        second: Optional[List[int]] = None
    else:
        cur, second = release_order(inst), initial_order(inst)
        if cur == second:
            second = None
    counter, deadline = run.counter, run.deadline
    lb = int(inst.h_array[np.arange(k), list(inst.starts)].sum()) if k else 0
    failed: Optional[int] = None
    for attempt in range(restarts + 1):
        stats.orders = attempt + 1
        try:
            paths, failed = plan_in_order(inst, cur, counter, expansion_limit, deadline, start_hold,
                                          deferrals=DEFAULT_DEFERRALS)
        except BudgetExceeded:
            return finish(MapfResult("timeout", lower_bound=lb,
                                    message=f"expansion limit of {expansion_limit} reached (prioritised planning)"))
        except TimeoutError:
            return finish(MapfResult("timeout", lower_bound=lb,
                                    message=f"time limit of {time_limit:g} s reached (prioritised planning)"))
        if paths is not None:
            full = [p for p in paths if p is not None]
            return finish(plan_result(full, lb, f"prioritised planning ({attempt} restarts); cost not bounded"))
        assert failed is not None
        if second is not None:  # the release order failed: the far-first order next
            cur, second = second, None
            continue
        if cur[0] == failed:
            # planning is deterministic: the same order would fail the same way again
            return finish(MapfResult("timeout", lower_bound=lb,
                                    message=f"prioritised planning failed {attempt + 1} times; agent {failed} fails "
                                            "even when planned first, so a restart would repeat the last attempt"))
        cur.remove(failed)
        cur.insert(0, failed)
    return finish(MapfResult("timeout", lower_bound=lb,
                            message=f"prioritised planning failed {restarts + 1} times (last: agent {failed})"))
