"""The reuse and pruning machinery of CBS: MDD pruning, constraint checks on paths, content keys,
"never again" cut-offs in the low level, against independent brute-force computations."""
from collections import deque

import numpy as np
import pytest
from cbs_bruteforce import random_grid

from agents.search.mapf.constraints import (
    EMPTY,
    FOREVER,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
from agents.search.mapf.instance import UNREACHABLE, MapfInstance
from agents.search.mapf.lowlevel import Counter, earliest_arrival, space_time_astar
from agents.search.mapf.mdd import build_mdd, mdds_dependent, prune_mdd
from agents.search.mapf.paths import AgentPath, satisfies


def grid(rng, h, w, p_block):
    """A random 4-connected grid as an adjacency list of neighbours."""
    n, edges, _ = random_grid(rng, h, w, p_block)
    adj = [[] for _ in range(n)]
    for u, v in edges:
        adj[u].append(v)
    return adj


def random_agent(rng, h, w, p_block, min_nodes):
    """A random grid with one agent whose goal is reachable: ``(adj, n, start, goal, instance)``,
    or ``None`` (too few free cells, or the goal cut off)."""
    adj = grid(rng, h, w, p_block)
    n = len(adj)
    if n < min_nodes:
        return None
    s, g = (int(x) for x in rng.choice(n, 2, replace=False))
    inst = MapfInstance(adj, [s], [g])
    if inst.h[0][s] >= UNREACHABLE:
        return None
    return adj, n, s, g, inst


def allowed(cons, v, t):
    """Whether being at ``v`` at time ``t`` is allowed by vertex / range constraints."""
    for c in cons:
        if isinstance(c, VertexConstraint) and (c.node, c.time) == (v, t):
            return False
        if isinstance(c, RangeConstraint) and c.node == v and c.start <= t <= c.end:
            return False
    return True


def brute_paths(inst, adj, s, g, cons, T):
    """Every walk of exactly ``T`` steps from ``s`` ending at ``g`` that meets ``cons`` (parked
    at ``g`` afterwards), by plain enumeration."""
    out = []

    def rec(path):
        t = len(path) - 1
        if t == T:
            if path[-1] == g:
                p = AgentPath([(v, k) for k, v in enumerate(path)], inst)
                if all(satisfies(p, c) for c in cons):
                    out.append(tuple(path))
            return
        for w in [path[-1]] + adj[path[-1]]:
            if allowed(cons, w, t + 1):
                rec(path + [w])

    if allowed(cons, s, 0):
        rec([s])
    return out


def random_constraints(rng, agent, n, horizon, k):
    out = []
    for _ in range(k):
        kind = rng.integers(4)
        v, t = int(rng.integers(n)), int(rng.integers(1, horizon))
        if kind == 0:
            out.append(VertexConstraint(agent, v, t))
        elif kind == 1:
            out.append(EdgeConstraint(agent, v, int(rng.integers(n)), t))
        elif kind == 2:
            out.append(RangeConstraint(agent, v, t, t + int(rng.integers(0, 3))))
        else:
            out.append(LengthConstraint(agent, int(rng.integers(0, horizon))))
    return out


@pytest.mark.parametrize("seed", range(12))
def test_pruned_mdd_is_the_built_mdd_and_holds_exactly_the_allowed_paths(seed):
    rng = np.random.default_rng(seed)
    made = random_agent(rng, 3, 4, 0.15, 4)
    if made is None:
        return
    adj, n, s, g, inst = made
    counter = Counter()
    base = EMPTY.add(*random_constraints(rng, 0, n, 6, 1))
    more = base.add(*random_constraints(rng, 0, n, 6, 2))
    cc_base, cc_more = (compile_constraints(c, n, g) for c in (base, more))
    p_base = space_time_astar(inst, 0, cc_base, None, float("inf"), counter)
    p_more = space_time_astar(inst, 0, cc_more, None, float("inf"), counter)
    if p_base is None or p_more is None:
        return
    T = p_more[-1][1]
    # the low level's cost is the brute-force optimum
    assert T == min(t for t in range(0, 12) if brute_paths(inst, adj, s, g, list(more), t))
    old = build_mdd(inst, 0, cc_base, p_base[-1][1])
    built = build_mdd(inst, 0, cc_more, T)
    # the states of all allowed paths of that cost are the MDD's levels
    paths = brute_paths(inst, adj, s, g, list(more), T)
    levels = [{p[t] for p in paths} for t in range(T + 1)]
    assert [set(lv) for lv in built.levels] == levels
    if old.cost == T:
        pruned = prune_mdd(old, cc_more)
        assert pruned is not None
        assert sorted(pruned.edges) == sorted(built.edges)
        assert [set(lv) for lv in pruned.levels] == levels


def test_satisfies_each_kind():
    adj = [[1], [0, 2], [1, 3], [2]]  # a line 0-1-2-3
    inst = MapfInstance(adj, [0], [3])
    p = AgentPath([(0, 0), (1, 1), (2, 2), (3, 3)], inst)
    assert not satisfies(p, VertexConstraint(0, 2, 2)) and satisfies(p, VertexConstraint(0, 2, 1))
    assert not satisfies(p, VertexConstraint(0, 3, 9))  # parked at its goal
    assert not satisfies(p, EdgeConstraint(0, 1, 2, 1)) and satisfies(p, EdgeConstraint(0, 2, 1, 1))
    assert not satisfies(p, RangeConstraint(0, 1, 0, 1)) and satisfies(p, RangeConstraint(0, 1, 2, 5))
    assert not satisfies(p, RangeConstraint(0, 3, 5, 7))  # parked inside the range
    assert not satisfies(p, RangeConstraint(0, 3, 0, FOREVER))
    assert satisfies(p, LengthConstraint(0, 2)) and not satisfies(p, LengthConstraint(0, 3))


def test_constraint_content_does_not_depend_on_the_order():
    a, b = VertexConstraint(0, 1, 2), EdgeConstraint(0, 1, 2, 3)
    x, y = EMPTY.add(a).add(b), EMPTY.add(b, a)
    assert x.key != y.key and x.content == y.content == frozenset({a, b})
    assert x.parent.content == frozenset({a}) and EMPTY.content == frozenset()


def brute_earliest(adj, s, target, cons, blocked, horizon=60):
    """Earliest time at ``target`` by breadth-first search over (node, time) states."""
    cc_forever = {c.node: c.start for c in cons if isinstance(c, RangeConstraint) and c.end >= FOREVER}
    seen = {(s, 0)}
    queue = deque([(s, 0)])
    while queue:
        v, t = queue.popleft()
        if v == target:
            return t
        if t >= horizon:
            continue
        for w in [v] + adj[v]:
            if w in blocked or not allowed(cons, w, t + 1):
                continue
            if w in cc_forever and t + 1 >= cc_forever[w]:
                continue
            if (w, t + 1) not in seen:
                seen.add((w, t + 1))
                queue.append((w, t + 1))
    return UNREACHABLE


@pytest.mark.parametrize("seed", range(16))
def test_never_again_cut_offs_keep_the_low_level_exact(seed):
    """Agents closed out of nodes for good: costs and earliest arrivals match brute force, and a
    goal cut off for good is reported infeasible."""
    rng = np.random.default_rng(100 + seed)
    made = random_agent(rng, 4, 4, 0.2, 5)
    if made is None:
        return
    adj, n, s, g, inst = made
    # even seeds close every neighbour of the goal (from early times: the goal may be cut off)
    closed = adj[g] if seed % 2 == 0 else [int(x) for x in rng.choice(n, 2, replace=False)]
    cons = [RangeConstraint(0, x, int(rng.integers(0, 8)), FOREVER) for x in closed if x not in (s, g)]
    cs = EMPTY.add(*cons)
    cc = compile_constraints(cs, n, g)
    counter = Counter()
    p = space_time_astar(inst, 0, cc, None, float("inf"), counter)
    # no constraint touches the goal, so the optimal cost is the earliest arrival there
    best = brute_earliest(adj, s, g, cons, frozenset())
    if best >= UNREACHABLE:
        assert p is None
    else:
        assert p is not None and p[-1][1] == best
    target = int(rng.integers(n))
    assert earliest_arrival(inst, 0, cc, target, frozenset(), float("inf"), counter) == \
        brute_earliest(adj, s, target, cons, frozenset())


@pytest.mark.parametrize("seed", range(16))
def test_mdd_avoidable_matches_the_enumerated_optimal_paths(seed):
    """``MDD.avoidable`` (unit time: its level shortcuts and its search alike) says whether some
    optimal path keeps off a node during a window, against every enumerated optimal path."""
    rng = np.random.default_rng(300 + seed)
    made = random_agent(rng, 3, 4, 0.1, 4)
    if made is None:
        return
    adj, n, s, g, inst = made
    cons = EMPTY.add(*random_constraints(rng, 0, n, 6, 2))
    cc = compile_constraints(cons, n, g)
    events = space_time_astar(inst, 0, cc, None, float("inf"), Counter())
    if events is None:
        return
    T = events[-1][1]
    mdd = build_mdd(inst, 0, cc, T)
    paths = brute_paths(inst, adj, s, g, list(cons), T)
    assert paths
    checked = 0
    for node in range(n):
        for start in range(T + 2):
            for end in (start, start + 1, start + 3, None):
                hi = T + 10 if end is None else end
                # a path is parked at its goal after T
                keeps_off = any(all(p[min(t, T)] != node for t in range(start, hi + 1)) for p in paths)
                assert mdd.avoidable(node, start, True, end) == keeps_off, (node, start, end)
                checked += 1
    assert checked > 0


def walks_conflict(p, q):
    """Whether two walks (each parked at its last node afterwards) meet at a node or swap."""
    T = max(len(p), len(q))

    def at(w, t):
        return w[min(t, len(w) - 1)]

    for t in range(T):
        if at(p, t) == at(q, t):
            return True
        if t + 1 < T and at(p, t) != at(p, t + 1) and at(p, t) == at(q, t + 1) and at(p, t + 1) == at(q, t):
            return True
    return False


@pytest.mark.parametrize("seed", range(24))
def test_mdds_dependent_matches_the_enumerated_optimal_paths(seed):
    """Two agents are dependent exactly when no pair of their optimal walks (under random
    constraints) avoids each other, by enumerating every pair."""
    rng = np.random.default_rng(500 + seed)
    adj = grid(rng, 3, 4, 0.1)
    n = len(adj)
    if n < 5:
        return
    starts = [int(x) for x in rng.choice(n, 2, replace=False)]
    goals = [int(x) for x in rng.choice(n, 2, replace=False)]
    inst = MapfInstance(adj, starts, goals)
    if any(inst.h[a][starts[a]] >= UNREACHABLE for a in range(2)):
        return
    mdds, walks = [], []
    for a in range(2):
        cons = EMPTY.add(*random_constraints(rng, a, n, 5, int(rng.integers(0, 3))))
        cc = compile_constraints(cons, n, goals[a])
        events = space_time_astar(inst, a, cc, None, float("inf"), Counter())
        if events is None:
            return
        T = events[-1][1]
        mdds.append(build_mdd(inst, a, cc, T))
        walks.append(brute_paths(inst, adj, starts[a], goals[a], list(cons), T))
    free = any(not walks_conflict(p, q) for p in walks[0] for q in walks[1])
    # the depth-first probe alone, the breadth-first search alone, and a probe cut short
    for probe in (None, 0, 3):
        assert mdds_dependent(mdds[0], mdds[1], probe_states=probe) == (not free)
        assert mdds_dependent(mdds[1], mdds[0], probe_states=probe) == (not free)
