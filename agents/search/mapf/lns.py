"""Large-neighbourhood repair: many agents where prioritised planning gives up.

Prioritised planning (:mod:`agents.search.mapf.prioritized`) plans each agent once around the
agents before it; in a dense crowd an agent may find no path at all, and the solve fails. The
repair here, in the spirit of "MAPF-LNS2: Fast Repairing for Multi-Agent Path Finding via Large
Neighborhood Search" (Li et al., AAAI 2022), never lets an agent fail: it accepts conflicts and
removes them afterwards.

1. **Initial plan**: prioritised planning, where an agent that finds no conflict-free path gets
   the path with the fewest conflicts instead (:func:`soft_sipp`).
2. **Repair**: while some agents conflict, pick a *neighbourhood* of a few agents (an agent in a
   conflict, the agents it conflicts with and theirs, the agents in the way of their shortest
   paths, then agents whose paths come near theirs), drop their paths and plan them again one
   by one, in random order, each on its least conflicting path against all the other paths;
   keep the new paths if the number of pairs of agents in conflict did not grow, else put the
   old ones back.

Conflicts are those of :func:`~agents.search.mapf.validate.validate`, kept in a
:class:`~agents.search.mapf.conflict_table.ConflictTable`. Every budget is counted in expansions, and the neighbourhoods
are drawn from a generator seeded by ``seed``, so a solve is a function of the instance, the
options and the seed; the wall-clock ``time_limit`` is only a safety net.
"""
from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Set

from .conflict_table import ConflictTable, occupancy, soft_sipp
from .instance import MapfInstance
from .prioritized import (
    SolveRun,
    check_common_options,
    default_start_hold,
    initial_order,
    no_plan_reason,
    plan_in_order,
    plan_result,
)
from .result import MapfResult
from .sipp import BudgetExceeded, Events
from .solver import DEFAULT_JOINT_CHECK_STATES

__all__ = ["ConflictTable", "DEFAULT_NEIGHBORHOOD_SIZE", "DEFAULT_REPAIR_EXPANSION_LIMIT", "RepairStats", "direct_path",
           "occupancy", "soft_sipp", "solve_lns"]

#: default expansions of one repair solve (initial plan and repair together)
DEFAULT_REPAIR_EXPANSION_LIMIT = 2_000_000
#: default number of agents re-planned together
DEFAULT_NEIGHBORHOOD_SIZE = 4


@dataclass
class RepairStats:
    """Statistics of one large-neighbourhood repair (its work and seconds are the result's)."""

    #: pairs of agents in conflict in the initial plan
    initial_conflicts: int = 0
    #: neighbourhoods re-planned
    neighbourhoods: int = 0
    #: neighbourhoods whose new paths were kept
    kept: int = 0


def direct_path(inst: MapfInstance, agent: int) -> Events:
    """``agent``'s shortest timed path when alone (first successor on a shortest path at each node)."""
    h = inst.h[agent]
    u, t = inst.starts[agent], 0
    events: Events = [(u, 0)]
    unit = inst.unit
    while h[u] > 0:
        for v, d in inst.succ_d[u][1:]:
            step = 1 if unit else d
            if h[v] + step == h[u]:
                u, t = v, t + step
                events.append((u, t))
                break
        else:  # not on a shortest path: cannot happen with true distances
            raise AssertionError(f"no shortest-path successor of node {u} for agent {agent}")
    return events


def _neighbourhood(rng: random.Random, inst: MapfInstance, conf: List[Set[int]], table: ConflictTable,
                   size: int) -> List[int]:
    """A few agents to re-plan together: an agent drawn among those in a conflict, the agents it
    conflicts with and theirs (breadth first), then the agents in the way of their shortest
    paths (those that the path each would take alone meets), then agents whose paths come near."""
    conflicted = [i for i, c in enumerate(conf) if c]
    first = rng.choice(conflicted)
    chosen = [first]
    seen = {first}
    frontier = deque([first])
    while frontier and len(chosen) < size:
        x = frontier.popleft()
        others = sorted(conf[x] - seen)
        rng.shuffle(others)
        for y in others[:size - len(chosen)]:
            seen.add(y)
            chosen.append(y)
            frontier.append(y)
    for pool in ("in the way", "nearby"):
        if len(chosen) >= size:
            break
        found: Set[int] = set()
        for x in chosen:
            if pool == "in the way":
                found |= table.conflicts(direct_path(inst, x), x)
            else:
                for node in {u for u, _ in table.paths[x]}:
                    found |= table.agents_at(node)
        extra = sorted(found - seen)
        rng.shuffle(extra)
        extra = extra[:size - len(chosen)]
        chosen.extend(extra)
        seen.update(extra)
    return chosen


def solve_lns(inst: MapfInstance, *, expansion_limit: Optional[int] = DEFAULT_REPAIR_EXPANSION_LIMIT,
              time_limit: Optional[float] = None, seed: int = 0,
              neighborhood_size: int = DEFAULT_NEIGHBORHOOD_SIZE, call_limit: Optional[int] = None,
              order: Optional[Sequence[int]] = None, start_hold: Optional[int] = None,
              joint_check_states: int = DEFAULT_JOINT_CHECK_STATES) -> MapfResult:
    """Large-neighbourhood repair of a prioritised plan that may hold conflicts; a
    :class:`~agents.search.mapf.result.MapfResult` (``solver`` ``"lns"``, ``work``: search expansions,
    ``stats``: a :class:`RepairStats`).

    Args:
        inst: the instance (either time model, with or without proximity).
        expansion_limit: search expansions over the whole solve, the initial plan included
            (``None``: no limit); reaching it ends the solve with status ``"timeout"``.
        time_limit: wall-clock seconds, a safety net (``None``: none).
        seed: seeds the draw of the neighbourhoods and of the order in which their agents are
            re-planned (the same seed, the same plan).
        neighborhood_size: how many agents are re-planned together (at least 1).
        call_limit: expansions of one agent's search (:func:`soft_sipp`) in the repair; a search
            that passes it leaves that neighbourhood as it was (``None``: no limit).
        order: the priority order of the initial plan (default
            :func:`~agents.search.mapf.prioritized.initial_order`).
        start_hold: as for :func:`~agents.search.mapf.prioritized.solve_prioritized`.
        joint_check_states: as for :func:`~agents.search.mapf.prioritized.solve_prioritized`: a
            small impossible part of the instance is reported ``"infeasible"`` before searching.

    Returns:
        status ``"suboptimal"`` (or ``"optimal"`` where the sum of costs equals the lower bound)
        with conflict-free paths, ``"timeout"`` (the message says which limit, and how many
        pairs of agents were still in conflict), or ``"infeasible"`` when some agent's goal
        cannot be reached from its start even alone, or the joint check proves that no plan
        exists.
    """
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    if isinstance(neighborhood_size, bool) or not isinstance(neighborhood_size, int) or neighborhood_size < 1:
        raise ValueError(f"neighborhood_size must be an integer >= 1, got {neighborhood_size!r}")
    if call_limit is not None and not (isinstance(call_limit, int) and call_limit >= 1):
        raise ValueError(f"call_limit must be an integer >= 1 or None, got {call_limit!r}")
    if start_hold is None:
        start_hold = default_start_hold(inst)
    if start_hold < 0:
        raise ValueError(f"start_hold must be >= 0, got {start_hold!r}")
    check_common_options(expansion_limit, time_limit, joint_check_states)
    run = SolveRun(expansion_limit, time_limit, "lns", RepairStats())
    k = inst.n_agents
    reason = no_plan_reason(inst, joint_check_states)
    if reason is not None:
        return run.finish(inst, MapfResult("infeasible", message=reason))
    first = list(order) if order is not None else initial_order(inst)
    if sorted(first) != list(range(k)):
        raise ValueError(f"order must be a permutation of the {k} agents")
    lb = sum(inst.h[i][inst.starts[i]] for i in range(k))
    rng = random.Random(seed)
    table = ConflictTable(inst)
    conf: List[Set[int]] = [set() for _ in range(k)]
    stats = run.stats
    phase = "initial plan"
    pairs = 0
    try:
        paths, failed = plan_in_order(inst, first, run.counter, expansion_limit, run.deadline, start_hold,
                                      soft=table)
        if paths is None:  # only a soft search past its limit fails, and there is none here
            raise AssertionError(f"agent {failed} got no path")
        for i in range(k):
            conf[i] = table.conflicts(table.paths[i], i)
        pairs = sum(len(c) for c in conf) // 2
        stats.initial_conflicts = pairs
        phase = "repair"
        while pairs:
            run.check_limits()
            stats.neighbourhoods += 1
            group = _neighbourhood(rng, inst, conf, table, neighborhood_size)
            before = {frozenset((i, j)) for i in group for j in conf[i]}
            old = {i: table.remove(i) for i in group}
            old_conf = {i: set(conf[i]) for i in group}
            for i in group:
                for j in conf[i]:
                    conf[j].discard(i)
                conf[i] = set()
            rng.shuffle(group)
            new_conf: Dict[int, Set[int]] = {}
            done = True
            after = 0
            for i in group:
                p = soft_sipp(inst, i, table, expansion_limit, run.counter, call_limit)
                if p is None:
                    done = False
                    break
                new_conf[i] = table.conflicts(p, i)
                table.reserve(i, p)
                after += len(new_conf[i])
                if after > len(before):  # more conflicts already: the old paths stay
                    done = False
                    break
            if done:
                for i, c in new_conf.items():
                    conf[i] = c
                    for j in c:
                        conf[j].add(i)
                pairs += after - len(before)
                stats.kept += 1
            else:
                for i in new_conf:
                    table.remove(i)
                for i in group:
                    table.reserve(i, old[i])
                    conf[i] = old_conf[i]
                    for j in conf[i]:
                        conf[j].add(i)
    except BudgetExceeded:
        return run.finish(inst, MapfResult("timeout", lower_bound=lb, message=(
            f"expansion limit of {expansion_limit} reached (large-neighbourhood repair, {phase}"
            f"{'' if phase == 'initial plan' else f'; {pairs} pairs of agents still in conflict'})")))
    except TimeoutError:
        return run.finish(inst, MapfResult("timeout", lower_bound=lb, message=(
            f"time limit of {time_limit:g} s reached (large-neighbourhood repair, {phase}"
            f"{'' if phase == 'initial plan' else f'; {pairs} pairs of agents still in conflict'})")))
    full = [table.paths[i] for i in range(k)]
    return run.finish(inst, plan_result(full, lb, (
        f"large-neighbourhood repair: {stats.initial_conflicts} pairs of agents in conflict in the initial plan, "
        f"{stats.neighbourhoods} neighbourhoods re-planned; cost not bounded")))
