"""The successor function the low-level searches share, against a direct reading of the rules."""
import heapq

import numpy as np
import pytest

from agents.search.mapf import (
    EMPTY,
    FOREVER,
    UNREACHABLE,
    EdgeConstraint,
    MapfInstance,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
from agents.search.mapf.paths import AgentPath, Reservation
from agents.search.mapf.successors import FIELD_BITS, FIELD_MASK, SPREAD_SHIFT, key_shift, make_successors

N_NODES = 7


def random_instance(rng, time_model):
    adj = [[(v, int(rng.integers(1, 4))) for v in range(N_NODES) if v != u and rng.random() < 0.35]
           for u in range(N_NODES)]
    return MapfInstance(adj, [0, 1, 2], [3, 4, 5], time_model=time_model)


def random_walk(rng, inst, start, steps):
    """Events of a random walk (waits included) from ``start``."""
    events, v, t = [(start, 0)], start, 0
    for _ in range(steps):
        w, d = inst.succ_d[v][int(rng.integers(len(inst.succ_d[v])))]
        v, t = w, t + (1 if inst.unit else d)
        events.append((v, t))
    return events


def random_constraints(rng, inst, agent):
    cons = EMPTY
    for _ in range(int(rng.integers(0, 10))):
        v, t, kind = int(rng.integers(N_NODES)), int(rng.integers(0, 8)), rng.random()
        if kind < 0.4:
            cons = cons.add(VertexConstraint(agent, v, t))
        elif kind < 0.6 and len(inst.succ[v]) > 1:
            cons = cons.add(EdgeConstraint(agent, v, inst.succ[v][1], t))
        elif kind < 0.8:
            cons = cons.add(RangeConstraint(agent, v, t, t + int(rng.integers(0, 3))))
        elif v != inst.goals[agent]:
            cons = cons.add(RangeConstraint(agent, v, t, FOREVER))
    return compile_constraints(cons, inst.n_nodes, inst.goals[agent])


def expected(inst, cc, res, h, v, t):
    """``[(code, f, conflicts, h), ...]`` of the state ``(v, t)``, read off the rules one by one."""
    N = inst.n_nodes
    out = []
    for w, d in inst.succ_d[v]:  # the wait first; every move takes one step under unit time
        nt = t + (1 if inst.unit else d)
        if h[w] >= UNREACHABLE:
            continue
        occupied = {v, w}
        if inst.unit:  # at w at time nt, having moved v -> w at t
            if nt * N + w in cc.vset or (w != v and (t * N + v) * N + w in cc.eset):
                continue
            if w in cc.forever and nt >= cc.forever[w]:
                continue
            conflicts = 0
            if res is not None:
                conflicts = ((w != v and (t * N + w) * N + v in res.moves) + (nt * N + w in res.occ)
                             + (w in res.parked and nt >= res.parked[w]))
        else:  # occupying both v and w during the steps t .. nt - 1
            steps = range(t, nt)
            if any(k * N + x in cc.vset for k in steps for x in occupied):
                continue
            if any(x in cc.forever and nt - 1 >= cc.forever[x] for x in occupied):
                continue
            conflicts = 0
            if res is not None:
                conflicts = (sum(k * N + x in res.occ for k in steps for x in occupied)
                             + sum(x in res.parked and nt - 1 >= res.parked[x] for x in occupied))
                if res.places:
                    conflicts = (conflicts << SPREAD_SHIFT) + (w != v and w in res.places)
        out.append((nt * N + w, nt + h[w], conflicts, h[w]))
    return out


@pytest.mark.parametrize("time_model", ["unit", "durative"])
@pytest.mark.parametrize("seed", range(12))
def test_successors_follow_the_constraints_and_count_the_conflicts(time_model, seed):
    rng = np.random.default_rng(seed)
    inst = random_instance(rng, time_model)
    N = inst.n_nodes
    others = [AgentPath(random_walk(rng, inst, inst.starts[b], 6), inst) for b in range(inst.n_agents)]
    for agent in range(inst.n_agents):
        cc = random_constraints(rng, inst, agent)
        for res in (None, Reservation(others, agent, inst), Reservation(others, agent, inst, spread="routes")):
            h = inst.h[agent]
            successors = make_successors(inst, cc, res, h, set(), 1 << 20)
            for t in range(9):
                for v in range(N):
                    got = successors(t * N + v, v, t, 0)
                    assert got == expected(inst, cc, res, h, v, t), (agent, v, t)
                    assert successors(t * N + v, v, t, 5) == [(c, f, k + 5, hw) for c, f, k, hw in got]


def test_the_search_rules_closed_states_horizon_bound_floor_and_improvements():
    rng = np.random.default_rng(3)
    inst = random_instance(rng, "durative")
    N, agent = inst.n_nodes, 0
    cc = compile_constraints(EMPTY, N, inst.goals[agent])
    h = inst.h[agent]
    v = inst.starts[agent]
    free = make_successors(inst, cc, None, h, set(), 1 << 20)(v, v, 0, 0)
    assert len(free) > 1
    # a closed state is left out
    closed = {free[1][0]}
    assert make_successors(inst, cc, None, h, closed, 1 << 20)(v, v, 0, 0) == [free[0]] + free[2:]
    # states from the horizon on share the horizon's code
    merged = make_successors(inst, cc, None, h, set(), 1)(v, v, 0, 0)
    assert [c for c, *_ in merged] == [min(c // N, 1) * N + c % N for c, *_ in free]
    # the bound on f
    limit = min(f for _, f, _, _ in free)
    assert make_successors(inst, cc, None, h, set(), 1 << 20, f_limit=limit)(v, v, 0, 0) == [
        s for s in free if s[1] <= limit]
    # the floor on the final arrival raises h
    raised = make_successors(inst, cc, None, h, set(), 1 << 20, floor=50)(v, v, 0, 0)
    assert raised == [(c, 50, k, 50 - c // N) for c, _, k, _ in free]
    # kept only where they improve on the best known, and recorded
    best, parent = {}, {}
    improving = make_successors(inst, cc, None, h, set(), 1 << 20, best=best, parent=parent)
    assert improving(v, v, 0, 0) == free
    assert parent == {c: v for c, *_ in free} and best == {c: (f << FIELD_BITS) | k for c, f, k, _ in free}
    assert improving(v, v, 0, 0) == []


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_pushed_keys_hold_the_successors_and_order_them_as_tuples(time_model):
    rng = np.random.default_rng(5)
    inst = random_instance(rng, time_model)
    N, L = inst.n_nodes, 1 << 20
    others = [AgentPath(random_walk(rng, inst, inst.starts[b], 6), inst) for b in range(inst.n_agents)]
    res = Reservation(others, 0, inst)
    cc = compile_constraints(EMPTY, N, inst.goals[0])
    listed = make_successors(inst, cc, res, inst.h[0], set(), L)
    heap = []
    pushing = make_successors(inst, cc, res, inst.h[0], set(), L, heap=heap)
    S1 = key_shift(L, N)
    S2, S3 = S1 + FIELD_BITS, S1 + 2 * FIELD_BITS
    want = []
    for t in range(6):
        for v in range(N):
            want += listed(t * N + v, v, t, 3)
            assert pushing(t * N + v, v, t, 3) == []
    keys = [heapq.heappop(heap) for _ in range(len(heap))]
    decoded = [(k & ((1 << S1) - 1), k >> S3, (k >> S2) & FIELD_MASK, (k >> S1) & FIELD_MASK) for k in keys]
    assert decoded == sorted(want, key=lambda s: (s[1], s[2], s[3], s[0]))
