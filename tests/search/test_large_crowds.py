"""What makes a thousand agents on a large buffer graph fast: the array form of the safe-interval
search (compiled where numba is installed), the validator's conflict search by occupied ranges,
and the start blockers from the near lists. Each must give what the plain form gives."""
import random
from typing import Dict, List, Optional, Tuple

import numpy as np
import pytest

from agents.search.config import SolverConfig
from agents.search.mapf import MapfInstance, Proximity, compiled, solve_prioritized, validate
from agents.search.mapf import sipp as sipp_module
from agents.search.mapf.prioritized import start_blockers
from agents.search.mapf.validate import _conflicts


def grid_instance(side: int, k: int, seed: int, radius: float = 1.5, durative: bool = True) -> MapfInstance:
    """A ``side`` x ``side`` 4-connected grid with random symmetric durations 1..3, ``k`` agents
    on random distinct starts and goals, proximity by Manhattan distance below ``radius``."""
    rng = random.Random(seed)
    n = side * side
    dur: Dict[Tuple[int, int], int] = {}
    for r in range(side):
        for c in range(side):
            u = r * side + c
            for dr, dc in ((0, 1), (1, 0)):
                if r + dr < side and c + dc < side:
                    v = (r + dr) * side + c + dc
                    dur[(u, v)] = dur[(v, u)] = rng.randint(1, 3)
    adj = [[(v, d) for (a, v), d in sorted(dur.items()) if a == u] for u in range(n)]
    xy = np.array([(u // side, u % side) for u in range(n)])
    manhattan = np.abs(xy[:, None, :] - xy[None, :, :]).sum(-1).astype(float)
    nodes = list(range(n))
    for _ in range(1000):  # starts (and goals) not near each other
        starts = rng.sample(nodes, k)
        goals = rng.sample(nodes, k)
        if all(manhattan[a, b] >= radius for ends in (starts, goals) for a in ends for b in ends if a != b):
            break
    return MapfInstance(adj, starts, goals, time_model="durative" if durative else "unit",
                        proximity=Proximity(manhattan, radius))


@pytest.fixture
def array_search(monkeypatch):
    """The safe-interval search in its array form (the compiled loop where numba is installed, its
    Python twin otherwise)."""
    if not compiled.AVAILABLE:
        monkeypatch.setattr(compiled, "AVAILABLE", True)
        monkeypatch.setattr(compiled, "sipp_durative", compiled._sipp_durative_py)
    monkeypatch.setattr(compiled, "ENABLED", True)


def solve_both(inst: MapfInstance, monkeypatch, **kwargs):
    monkeypatch.setattr(compiled, "ENABLED", False)
    plain = solve_prioritized(inst, **kwargs)
    monkeypatch.setattr(compiled, "ENABLED", True)
    fast = solve_prioritized(inst, **kwargs)
    return plain, fast


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("k", [8, 12])  # solved, and given up (prioritised planning is incomplete)
def test_the_array_search_plans_what_the_plain_one_plans(array_search, monkeypatch, seed, k):
    inst = grid_instance(8, k, seed)
    plain, fast = solve_both(inst, monkeypatch)
    assert plain.status == fast.status and plain.message == fast.message
    assert fast.paths == plain.paths and fast.soc == plain.soc
    assert fast.work == plain.work  # the same work, counted the same
    if fast.solved:
        assert validate(inst, None, None, fast.paths) == []


def test_the_array_search_spends_the_same_budget(array_search, monkeypatch):
    inst = grid_instance(8, 8, 1)
    free = solve_prioritized(inst)
    assert free.solved and free.work > 100
    limit = free.work // 2
    plain, fast = solve_both(inst, monkeypatch, expansion_limit=limit)
    assert plain.status == fast.status == "timeout"
    assert "expansion limit" in fast.message
    assert fast.work == plain.work == limit + 1


def test_the_array_search_keeps_holds_and_releases(array_search):
    # a table whose intervals change between searches: the arrays follow every change
    inst = grid_instance(5, 3, 0)
    table = sipp_module.interval_table(inst)
    assert isinstance(table, sipp_module.ArrayIntervalTable)
    table.hold(1, inst.starts[1], sipp_module.FOREVER)
    first = sipp_module.sipp(inst, 0, table)
    table.release(1)
    table.reserve(1, [(inst.starts[1], 0)])
    again = sipp_module.sipp(inst, 0, table)
    table2 = sipp_module.IntervalTable(inst)
    table2.hold(1, inst.starts[1], sipp_module.FOREVER)
    assert sipp_module.sipp(inst, 0, table2) == first
    table2.release(1)
    table2.reserve(1, [(inst.starts[1], 0)])
    assert sipp_module.sipp(inst, 0, table2) == again


@pytest.mark.parametrize("seed", range(3))
def test_the_array_table_keeps_what_the_list_table_keeps(array_search, seed):
    # random holds, releases and reserved paths: the same safe intervals and holders at every node,
    # also after the arrays outgrow their first size
    rng = random.Random(seed)
    inst = grid_instance(6, 6, seed, radius=2.5)
    plain = sipp_module.IntervalTable(inst)
    fast = sipp_module.ArrayIntervalTable(inst, capacity=4, intervals=1)
    n, forever = inst.n_nodes, sipp_module.FOREVER
    for step in range(60):
        agent = rng.randrange(inst.n_agents)
        what = rng.random()
        if what < 0.3:
            node, last = rng.randrange(n), rng.choice([0, 5, forever])
            for table in (plain, fast):
                table.hold(agent, node, last)
        elif what < 0.5:
            for table in (plain, fast):
                table.release(agent)
        else:
            t, u, events = rng.randrange(20), rng.randrange(n), []
            for _ in range(rng.randint(1, 6)):
                events.append((u, t))
                t += rng.randint(1, 4)
                u = rng.choice([u] + [v for v, _ in inst.succ_d[u][1:]])
            events.append((u, t))
            for table in (plain, fast):
                table.reserve(agent, events)
        if step % 7 == 0 or step == 59:
            for v in range(n):
                assert fast.safe(v) == plain.safe(v), (step, v)
                assert fast.holders(v) == plain.holders(v), (step, v)
    assert len(fast.e_next) > 4 and fast.search.cap > 1  # the arrays outgrew their first size


def test_unit_time_keeps_the_plain_search(array_search, monkeypatch):
    inst = grid_instance(6, 8, 1, durative=False)
    plain, fast = solve_both(inst, monkeypatch)
    assert fast.paths == plain.paths and fast.status == plain.status


@pytest.mark.skipif(not compiled.AVAILABLE, reason="numba is not installed")
def test_the_compiled_loop_is_the_python_one():
    assert compiled.sipp_durative is not compiled._sipp_durative_py
    assert compiled.sipp_durative.py_func is compiled._sipp_durative_py


def _blocks(inst, goal, start):
    """The definition: an agent parked at ``goal`` blocks one waiting at ``start``."""
    return goal == start or (inst.near_mat is not None and bool(inst.near_mat[goal, start]))


def test_start_blockers_are_the_pairs_that_block():
    for seed in range(4):
        inst = grid_instance(6, 10, seed, radius=2.5)
        got = start_blockers(inst)
        for i in range(inst.n_agents):
            want = [j for j in range(inst.n_agents) if j != i and _blocks(inst, inst.goals[i], inst.starts[j])]
            assert got[i] == want


# ------------------------------------------------------------------------------------------------
# the validator's conflicts against every pair at every time
# ------------------------------------------------------------------------------------------------
def _timeline(events: List[Tuple[int, int]], horizon: int, unit: bool) -> List[Tuple[int, ...]]:
    out: List[Tuple[int, ...]] = []
    for (u, t0), (v, t1) in zip(events, events[1:]):
        occ = (u,) if (unit or u == v) else (u, v)
        out.extend([occ] * (t1 - t0))
    while len(out) <= horizon:
        out.append((events[-1][0],))
    return out


def conflicts_pair_by_pair(ok: Dict[int, List[Tuple[int, int]]], unit: bool,
                           near: Optional[np.ndarray]) -> List[Tuple[int, int, int, str]]:
    """``(a, b, t, kind)`` of every conflict, checking every pair of agents at every time."""
    agents = sorted(ok)
    horizon = max(ev[-1][1] for ev in ok.values()) + 1
    occ = {k: _timeline(ok[k], horizon, unit) for k in agents}
    found = []
    for ia, a in enumerate(agents):
        for b in agents[ia + 1:]:
            for t in range(horizon + 1):
                sa, sb = occ[a][t], occ[b][t]
                if any(x in sb for x in sa):
                    found.append((a, b, t, "vertex"))
                elif near is not None and any(x != y and near[x, y] for x in sa for y in sb):
                    found.append((a, b, t, "proximity"))
                if unit and t < horizon:
                    na, nb = occ[a][t + 1][0], occ[b][t + 1][0]
                    if sa[0] != na and sa[0] == nb and na == sb[0]:
                        found.append((a, b, t, "swap"))
    return found


@pytest.mark.parametrize("unit", [False, True])
def test_the_validator_finds_every_conflict_pair_by_pair_finds(unit):
    rng = random.Random(7)
    seen_conflicts = 0
    for trial in range(150):
        inst = grid_instance(4, 4, trial, durative=not unit)
        near = inst.near_mat
        ok: Dict[int, List[Tuple[int, int]]] = {}
        for a in range(inst.n_agents):  # random walks, waits included
            u, t = inst.starts[a], 0
            events = [(u, 0)]
            for _ in range(rng.randint(0, 6)):
                if rng.random() < 0.3:
                    t += rng.randint(1, 2)
                    events.append((u, t))
                else:
                    v, d = rng.choice(inst.succ_d[u][1:])
                    t += 1 if unit else d
                    events.append((v, t))
                    u = v
            ok[a] = events
        want = conflicts_pair_by_pair(ok, unit, near)
        got = _conflicts(ok, unit, near)
        seen_conflicts += bool(want)
        assert len(got) == len(want)
        for (a, b, t, kind), message in zip(want, got):
            assert str(a) in message and str(b) in message and (f"t={t}" in message or f"[{t}, {t + 1})" in message)
            if kind == "swap":
                assert message.startswith("swap conflict")
            elif kind == "vertex":
                assert "vertex" in message or ("target" in message and "proximity radius" not in message)
            else:
                assert "proximity" in message
    assert seen_conflicts > 20  # the walks do collide


@pytest.mark.parametrize("seed", range(4))
def test_the_release_order_is_the_same_either_way(array_search, monkeypatch, seed):
    from agents.search.mapf.prioritized import release_order

    inst = grid_instance(7, 14, seed, radius=2.5)
    fast = release_order(inst)
    monkeypatch.setattr(compiled, "ENABLED", False)
    assert release_order(inst) == fast


@pytest.mark.parametrize("nodes", [400, 1500])
def test_the_prioritized_budget_grows_with_the_graph(monkeypatch, nodes):
    import agents.search.mapf.registry as registry_module
    from agents.search.mapf import MapfResult
    from agents.search.planner import REFERENCE_BUFFER_NODES, BufferPlanner

    rng = np.random.default_rng(0)
    side = np.sqrt(nodes) * 1.5
    obs = rng.uniform(0, side, size=(nodes, 2))

    def pairwise(a, b):
        d = np.linalg.norm(a[:, None] - b[None], axis=-1)
        return d, np.zeros_like(d)

    D, C = pairwise(obs, obs)
    planner = BufferPlanner(obs, D, C, pairwise, solver=SolverConfig(name="prioritized",
                                                                     prioritized_expansions_per_agent=100))
    assert planner.size_scale() == max(1.0, nodes / REFERENCE_BUFFER_NODES)
    seen = {}

    def spy(inst, expansion_limit=None, **kwargs):
        seen["limit"] = expansion_limit
        return MapfResult("timeout", message="spied", solver="prioritized")

    monkeypatch.setattr(registry_module, "solve_prioritized", spy)
    k = 3
    picks = rng.choice(nodes, size=2 * k, replace=False)
    planner.plan(obs[picks[:k]] + 0.1, obs[picks[k:]] + 0.1)
    assert seen["limit"] == int(100 * k * planner.size_scale())  # (a sparse graph: work_scale is 1)


def test_a_bordered_matrix_reads_as_the_dense_one():
    from agents.search.graph.build import BorderedMatrix

    rng = np.random.default_rng(0)
    full = rng.random((9, 9))
    inner = full[:7, :7].copy()
    b = BorderedMatrix.of(full, inner)
    assert b.shape == full.shape and len(b) == 9
    for i in range(9):
        for j in range(9):
            assert b[i, j] == full[i, j] and b[np.int64(i), np.int64(j)] == full[i, j]
        assert np.array_equal(b[i, :7], full[i, :7]) and np.array_equal(b[:7, i], full[:7, i])
        assert np.array_equal(b[i, :], full[i, :]) and np.array_equal(b[:, i], full[:, i])
    assert b[-1, -2] == full[-1, -2]
    assert np.array_equal(np.asarray(b), full) and np.array_equal(b[[1, 8], [2, 7]], full[[1, 8], [2, 7]])
    with pytest.raises(ValueError, match="bordered matrix"):
        BorderedMatrix(inner, full[7:, :7], full[:, 7:])


@pytest.mark.parametrize("d_max", [None, 4.0])
def test_passing_edges_compare_only_the_nodes_near_a_place(d_max):
    # the pairs of nodes near each place give what every pair gives, on the edges (pairs closer than d_max)
    from agents.search.graph.build import passing_edges, place_passing

    rng = np.random.default_rng(3)
    pts = rng.random((60, 2)) * 10
    places = rng.random((4, 2)) * 10

    def dist(a, b):
        d = np.linalg.norm(a[:, None] - b[None], axis=-1) * rng.uniform(1.0, 1.2, (len(a), len(b)))
        return d, np.zeros_like(d)

    D, _ = dist(pts, pts)
    to_place, _ = dist(pts, places)
    from_place, _ = dist(places, pts)
    tables = iter([(to_place, None), (from_place, None)])
    pairs = passing_edges(D, pts, lambda a, b: next(tables), places, slack=0.5, d_max=d_max)
    out = np.zeros(D.shape, bool)
    out[pairs[:, 0], pairs[:, 1]] = True
    assert len(np.unique(pairs, axis=0)) == len(pairs)
    every = np.zeros_like(out)
    for j in range(len(places)):
        every |= to_place[:, j, None] + from_place[j, None, :] <= D + 0.5
    np.fill_diagonal(every, False)
    edges = np.ones_like(out) if d_max is None else D < d_max
    assert out.any() and np.array_equal(out, every & edges)
    # the first nodes a buffer whose distances and pairs through each place are known: the same pairs, with
    # few other nodes (compared with all places at once) and with more (place by place)
    for have in (50, 57):
        known = (to_place[:have], from_place[:, :have])
        known_pairs = [place_passing(D[:have, :have], to_place[:have, j], from_place[j, :have], 0.5, d_max)
                       for j in range(len(places))]
        tables = iter([(to_place[have:], None), (from_place[:, have:], None)])
        again = passing_edges(D, pts, lambda a, b, t=tables: next(t), places, slack=0.5, d_max=d_max, known=known,
                              known_pairs=known_pairs)
        assert np.array_equal(again, pairs)
        assert any(len(k) for k in known_pairs) and any((pairs >= have).any(axis=1) & (pairs < have).any(axis=1))
    with pytest.raises(ValueError, match="known_pairs needs known"):
        passing_edges(D, pts, lambda a, b: (to_place, None), places, slack=0.5, known_pairs=known_pairs)
