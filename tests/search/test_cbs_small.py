"""CBS on hand-built graphs: swaps, crossings, bottlenecks, target conflicts, limits, API."""
import dataclasses

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc
from scipy import sparse

from agents.search.mapf import (
    EDGE,
    EMPTY,
    FOREVER,
    TARGET,
    VERTEX,
    CBSSolver,
    Conflict,
    CTNode,
    EdgeConstraint,
    LengthConstraint,
    MapfInstance,
    Proximity,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
    integer_durations,
    solve_cbs,
    validate,
)


def undirected(n, pairs, dur=None):
    """Adjacency list with (v, duration) entries for undirected edges."""
    adj = [[] for _ in range(n)]
    edges = {}
    for k, (u, v) in enumerate(pairs):
        d = 1 if dur is None else dur[k]
        adj[u].append((v, d))
        adj[v].append((u, d))
        edges[(u, v)] = edges[(v, u)] = d
    return adj, edges


def solve_and_check(adj, edges, starts, goals, time_model="unit", **kw):
    res = solve_cbs(adj, starts, goals, time_model=time_model, time_limit=20, **kw)
    expected = brute_force_soc(len(adj), edges, starts, goals, unit=time_model == "unit")
    assert res.status == "optimal", res.message
    assert res.soc == expected
    assert validate(adj, starts, goals, res.paths, time_model=time_model) == []
    return res


# corridor 0-1-2-3 with a side pocket 4 off node 1
POCKET = [(0, 1), (1, 2), (2, 3), (1, 4)]


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_corridor_swap_uses_the_side_pocket(time_model):
    adj, edges = undirected(5, POCKET)
    res = solve_and_check(adj, edges, [0, 3], [3, 0], time_model)
    visited = {v for path in res.paths for v, _ in path}
    assert 4 in visited  # one agent steps aside
    if time_model == "unit":
        assert res.soc == 8 and res.makespan == 5


def test_corridor_swap_with_long_durative_edges():
    adj, edges = undirected(5, POCKET, dur=[2, 1, 3, 2])
    res = solve_and_check(adj, edges, [0, 3], [3, 0], "durative")
    for path in res.paths:  # moves take exactly their durations
        for (u, t0), (v, t1) in zip(path, path[1:]):
            assert t1 - t0 == (1 if u == v else edges[(u, v)])


def test_crossing_at_a_junction_costs_one_wait():
    # plus shape: centre 0, arms 1-5 (north-south) and 2-6 (west-east) of length two
    adj, edges = undirected(9, [(0, 1), (1, 5), (0, 2), (2, 6), (0, 3), (3, 7), (0, 4), (4, 8)])
    res = solve_and_check(adj, edges, [5, 6], [7, 8])
    assert res.soc == 4 + 4 + 1


def test_bottleneck_between_two_rooms():
    # two triangles joined by the single node 6; three agents cross
    pairs = [(0, 1), (1, 2), (0, 2), (2, 6), (6, 3), (3, 4), (4, 5), (3, 5)]
    adj, edges = undirected(7, pairs)
    res = solve_and_check(adj, edges, [0, 1, 4], [5, 3, 0])
    through = [t for path in res.paths for v, t in path if v == 6]
    assert len(through) == len(set(through))  # never two agents in the bottleneck at once


def test_target_conflict_delays_the_parked_agent():
    # path 0-1-2-3 with node 4 beside 2; agent 0 goes 4 -> 2, agent 1 goes 0 -> 3 through 2
    adj, edges = undirected(5, [(0, 1), (1, 2), (2, 3), (2, 4)])
    for kw in ({}, {"vanilla": True}, {"target_reasoning": False}):
        res = solve_and_check(adj, edges, [4, 0], [2, 3], **kw)
        assert res.soc == 6
        assert res.paths[0][-1] == (2, 3)  # arrives only after agent 1 has passed node 2


@pytest.mark.parametrize("time_model", ["unit", "durative"])
@pytest.mark.parametrize("n", [2, 3, 6])
def test_swap_on_a_path_graph_is_infeasible(time_model, n):
    adj, _ = undirected(n, [(i, i + 1) for i in range(n - 1)])
    res = solve_cbs(adj, [0, n - 1], [n - 1, 0], time_model=time_model, time_limit=10)
    assert res.status == "infeasible"
    assert res.paths is None and "cannot both reach" in res.message


def test_unreachable_goal_is_infeasible_immediately():
    adj = [[1], [], [1]]  # directed: nothing leaves node 1
    res = solve_cbs(adj, [1, 2], [0, 1])
    assert res.status == "infeasible" and "unreachable" in res.message
    assert res.stats.hl_expanded == 0


def test_bad_input_raises_clear_errors():
    adj, _ = undirected(3, [(0, 1), (1, 2)])
    with pytest.raises(ValueError, match="share the start"):
        solve_cbs(adj, [0, 0], [1, 2])
    with pytest.raises(ValueError, match="share the goal"):
        solve_cbs(adj, [0, 1], [2, 2])
    with pytest.raises(ValueError, match="not in the graph"):
        solve_cbs(adj, [0, 7], [1, 2])
    with pytest.raises(ValueError, match="starts but"):
        solve_cbs(adj, [0, 1], [2])
    with pytest.raises(ValueError, match="integer durations"):
        solve_cbs(np.array([[0, 1.5], [1.5, 0]]), [0], [1], time_model="durative")
    with pytest.raises(ValueError, match="time_model"):
        solve_cbs(adj, [0], [1], time_model="continuous")
    with pytest.raises(ValueError, match="suboptimality"):
        solve_cbs(adj, [0], [1], suboptimality=0.5)


def test_durative_model_forbids_following_closely():
    # path 0-1-2-3; agent 0 goes 1 -> 3, agent 1 follows 0 -> 2
    adj, edges = undirected(4, [(0, 1), (1, 2), (2, 3)])
    unit = solve_and_check(adj, edges, [1, 0], [3, 2], "unit")
    durative = solve_and_check(adj, edges, [1, 0], [3, 2], "durative")
    assert unit.soc == 4  # following in lockstep is fine under unit time
    assert durative.soc == 5  # the follower must wait one step


def test_graph_formats_agree():
    adj, edges = undirected(5, POCKET, dur=[2, 1, 3, 2])
    n = 5
    dense = np.zeros((n, n))
    for (u, v), d in edges.items():
        dense[u, v] = d
    csr = sparse.csr_matrix(dense)
    mapping = {u: row for u, row in enumerate(adj)}
    socs = {solve_cbs(g, [0, 3], [3, 0], time_model="durative").soc for g in (adj, dense, csr, mapping)}
    assert len(socs) == 1


def test_integer_durations_round_up():
    d = integer_durations(np.array([[0, 0.2, 2.01], [1.0, 0, np.inf], [0, 3.0, 0]]))
    assert d.toarray().tolist() == [[0, 1, 3], [1, 0, 0], [0, 3, 0]]


def test_proximity_keeps_agents_apart():
    # a 3x4 grid; with radius 1.5 agents in neighbouring rows cannot pass each other
    w, h = 4, 3
    pos = np.array([[x, y] for y in range(h) for x in range(w)], float)
    pairs = [(y * w + x, y * w + x + 1) for y in range(h) for x in range(w - 1)]
    pairs += [(y * w + x, (y + 1) * w + x) for y in range(h - 1) for x in range(w)]
    adj, edges = undirected(w * h, pairs)
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    prox = Proximity(dist, 1.5)
    near = dist < 1.5
    np.fill_diagonal(near, False)
    starts, goals = [4, 7], [7, 4]  # swap the two ends of the middle row
    free = solve_cbs(adj, starts, goals)
    res = solve_cbs(adj, starts, goals, proximity=prox)
    assert res.status == "optimal"
    assert res.soc == brute_force_soc(w * h, edges, starts, goals, near=near) > free.soc
    assert validate(adj, starts, goals, res.paths, proximity=prox) == []
    assert any("proximity" in m for m in validate(adj, starts, goals, free.paths, proximity=prox))
    for model in ("unit", "durative"):
        r = solve_cbs(adj, starts, goals, proximity=prox, time_model=model)
        assert validate(adj, starts, goals, r.paths, proximity=prox, time_model=model) == []
    # starts within the radius: infeasible from the outset
    res = solve_cbs(adj, [0, 1], [3, 7], proximity=(dist, 1.5))
    assert res.status == "infeasible" and "closer than" in res.message


def _dense_grid_instance():
    """A 6 x 6 open grid with 20 agents: not solvable in a millisecond."""
    h = w = 6
    pairs = [(r * w + c, r * w + c + 1) for r in range(h) for c in range(w - 1)]
    pairs += [(r * w + c, (r + 1) * w + c) for r in range(h - 1) for c in range(w)]
    adj, _ = undirected(h * w, pairs)
    rng = np.random.default_rng(0)
    return adj, rng.choice(h * w, 20, replace=False).tolist(), rng.choice(h * w, 20, replace=False).tolist()


def test_time_and_node_limits_end_with_timeout():
    adj, starts, goals = _dense_grid_instance()
    res = solve_cbs(adj, starts, goals, time_limit=0.02)
    assert res.status == "timeout" and res.paths is None and "time limit" in res.message
    assert res.runtime_s < 1.0
    res = solve_cbs(adj, starts, goals, node_limit=0, time_limit=30)
    assert res.status == "timeout" and "node limit" in res.message


@pytest.mark.parametrize("suboptimality", [1.0, 1.01])
def test_memory_limit_ends_with_timeout_and_says_so(monkeypatch, suboptimality):
    import agents.search.mapf.context as context_module

    # a process that seems to grow by 1 MiB every time the guard looks at it
    reads = iter(range(10**9))
    monkeypatch.setattr(context_module, "_rss_bytes", lambda: next(reads) * (1 << 20))
    adj, starts, goals = _dense_grid_instance()
    res = solve_cbs(adj, starts, goals, time_limit=60, memory_limit_mb=3, suboptimality=suboptimality)
    assert res.status == "timeout" and res.paths is None
    assert "memory limit" in res.message and "3 MiB" in res.message
    assert res.stats.hl_expanded > 0
    # with the guard off the same search is stopped only by its node limit
    res = solve_cbs(adj, starts, goals, time_limit=60, memory_limit_mb=None, node_limit=600,
                    suboptimality=suboptimality)
    assert "memory" not in res.message


def test_memory_limit_reads_the_real_process_size():
    import agents.search.mapf.context as context_module

    rss = context_module._rss_bytes()
    assert rss is None or rss > 1 << 20  # a Python process with numpy is larger than 1 MiB
    adj, _ = undirected(4, [(0, 1), (1, 2), (2, 3)])
    res = solve_cbs(adj, [0], [3], memory_limit_mb=64)
    assert res.status == "optimal" and res.soc == 3
    with pytest.raises(ValueError, match="memory_limit_mb"):
        solve_cbs(adj, [0], [3], memory_limit_mb=0)


def test_same_input_same_answer():
    adj, _ = undirected(9, [(0, 1), (1, 2), (3, 4), (4, 5), (6, 7), (7, 8), (0, 3), (3, 6), (1, 4), (4, 7),
                            (2, 5), (5, 8)])
    runs = [solve_cbs(adj, [0, 2, 6, 8], [8, 6, 2, 0]) for _ in range(3)]
    assert all(r.paths == runs[0].paths for r in runs)
    assert len({(r.soc, r.stats.hl_expanded, r.stats.hl_generated, r.work) for r in runs}) == 1


def test_result_helpers():
    adj, edges = undirected(5, POCKET, dur=[2, 1, 3, 2])
    res = solve_and_check(adj, edges, [0, 3], [3, 0], "durative")
    seqs = res.node_sequences()
    for path, seq in zip(res.paths, seqs):
        assert len(seq) == path[-1][1] + 1
        for v, t in path:
            assert seq[t] == v
    padded = res.node_sequences(pad=True)
    assert all(len(s) == res.makespan + 1 for s in padded)
    deps = res.departures(0)
    assert deps[0][0] == 0 and deps[-1] == res.paths[0][-1]
    assert all(t0 < t1 for (_, t0), (_, t1) in zip(deps, deps[1:]))
    d = res.to_dict()
    assert d["status"] == "optimal" and d["soc"] == res.soc and len(d["paths"]) == 2


def test_ctnode_order():
    def node(g, h, conflicts, i):
        n = CTNode(g, [], [], {}, i, h=h)
        n.n_conflicts = conflicts
        return n

    a = node(10, 0, 3, 5)  # f = 10
    b = node(9, 2, 1, 6)  # f = 11
    c = node(11, 0, 0, 1)  # f = 11, no conflicts
    d = node(10, 0, 3, 2)  # like a, created earlier
    e = node(8, 2, 1, 9)  # f = 10, fewer conflicts
    assert a < b and not b < a  # lower cost bound first
    assert c < b  # same bound: fewer conflicts first
    assert d < a and not a < d  # then creation order
    assert e < d  # fewer conflicts beat creation order
    assert sorted([a, b, c, d, e]) == [e, d, a, c, b]
    assert not a < a


def test_constraints_are_small_frozen_values():
    v = VertexConstraint(0, 3, 5)
    assert v == VertexConstraint(0, 3, 5) and hash(v) == hash(VertexConstraint(0, 3, 5))
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.time = 6  # type: ignore[misc]
    cs = EMPTY.add(v, EdgeConstraint(0, 1, 2, 4), RangeConstraint(0, 7, 2, 4), LengthConstraint(0, 9))
    assert list(cs) == [v, EdgeConstraint(0, 1, 2, 4), RangeConstraint(0, 7, 2, 4), LengthConstraint(0, 9)]
    assert len(cs) == 4 and len(EMPTY) == 0
    cc = compile_constraints(cs, 10, goal=3)
    assert 5 * 10 + 3 in cc.vset and (4 * 10 + 1) * 10 + 2 in cc.eset
    assert {t * 10 + 7 for t in (2, 3, 4)} <= cc.vset
    assert cc.goal_min == 9  # the length constraint beats the vertex constraint at the goal (5)
    assert compile_constraints(EMPTY.add(RangeConstraint(0, 3, 0)), 10, goal=3).impossible


def test_conflict_branches():
    vertex = Conflict(VERTEX, 0, 1, 4, 7, 7)
    assert vertex.branches() == [(0, (VertexConstraint(0, 7, 4),)), (1, (VertexConstraint(1, 7, 4),))]
    edge = Conflict(EDGE, 0, 1, 2, 5, 6)
    assert edge.branches() == [(0, (EdgeConstraint(0, 5, 6, 2),)), (1, (EdgeConstraint(1, 6, 5, 2),))]
    target = Conflict(TARGET, 0, 1, 8, 3, 3)
    assert target.branches() == [(0, (LengthConstraint(0, 8),)), (1, (RangeConstraint(1, 3, 8, FOREVER),))]
    assert target.branches(target_reasoning=False)[1] == (1, (VertexConstraint(1, 3, 8),))


def test_instance_and_solver_reuse():
    adj, _ = undirected(5, POCKET)
    inst = MapfInstance(adj, [0, 3], [3, 0])
    assert inst.h[0][0] == 3 and inst.unreachable_agents() == []
    full = CBSSolver(inst).solve()
    plain = CBSSolver(inst, vanilla=True).solve()
    ecbs = CBSSolver(inst, suboptimality=1.5).solve()
    assert full.soc == plain.soc == 8
    assert ecbs.soc <= 1.5 * 8
    with pytest.raises(ValueError):
        CBSSolver(inst, [0], [1])
