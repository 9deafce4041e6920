"""The priority inheritance stepper: plans checked by validate on small random graphs and grids
(durative edges, proximity), crowds where prioritised planning gives up, agents parked for good
at goals with no way out, determinism, budgets and bad input."""
import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid
from test_cbs_bruteforce import adjacency, pick, random_graph
from test_planner import _crossing_problem, _validate_plan, euclid_pairwise, grid_points, make_planner
from test_prioritized import random_proximity

from agents.search.mapf import MapfInstance, solve_pibt, solve_prioritized, validate


def open_grid(n):
    return [[(r + dr) * n + c + dc for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))
             if 0 <= r + dr < n and 0 <= c + dc < n] for r in range(n) for c in range(n)]


def buffer_like(seed, n=120, k=30, side=10.0, r_edge=1.6, r_prox=0.6, step=0.5):
    """An instance shaped like the planner's problem graph: ``n`` random points joined within
    ``r_edge`` (durations: length / ``step``, rounded up), each agent's start a node with edges
    out only and its goal a node with edges in only; nodes closer than ``r_prox`` are near.
    Starts are ``r_prox`` apart from each other, and so are goals."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, side, (n, 2))

    def place():
        out = []
        while len(out) < k:
            p = rng.uniform(0, side, 2)
            if all(np.hypot(*(p - q)) >= r_prox for q in out):
                out.append(p)
        return out

    allp = np.vstack([pts, place(), place()])
    dist = np.linalg.norm(allp[:, None] - allp[None], axis=-1)
    graph = np.zeros_like(dist)
    starts, goals = list(range(n, n + k)), list(range(n + k, n + 2 * k))
    for a in list(range(n)) + starts:
        for b in range(n):
            if a != b and dist[a, b] < r_edge:
                graph[a, b] = np.ceil(dist[a, b] / step)
    for a in range(n):
        for g in goals:
            if dist[a, g] < r_edge:
                graph[a, g] = np.ceil(dist[a, g] / step)
    return MapfInstance(graph, starts, goals, time_model="durative", proximity=(dist, r_prox))


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_plans_on_random_small_graphs_are_valid(time_model):
    solved = 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(5, 9))
        edges = random_graph(rng, n, 0.3, directed=seed % 3 == 0, max_dur=1 if time_model == "unit" else 3)
        prox, near = random_proximity(rng, n, 0.1) if seed % 2 else (None, None)
        k = int(rng.integers(2, 4))
        starts, goals = pick(rng, n, k, crossing=seed % 4 == 1)
        adj = adjacency(n, edges)
        inst = MapfInstance(adj, starts, goals, time_model=time_model, proximity=prox)
        res = solve_pibt(inst, expansion_limit=20_000)
        if res.solved:
            solved += 1
            assert validate(adj, starts, goals, res.paths, time_model=time_model, proximity=prox) == [], res.paths
            assert res.soc == sum(p[-1][1] for p in res.paths)
            assert res.soc >= res.lower_bound
        elif res.status == "infeasible":  # proved: the brute force finds no plan either
            assert brute_force_soc(n, edges, starts, goals, unit=time_model == "unit", near=near) is None
        else:
            assert res.status == "timeout" and res.message
    assert solved >= 38, solved


@pytest.mark.parametrize("seed", range(6))
def test_plans_on_grids_with_durative_edges_and_proximity_are_valid(seed):
    rng = np.random.default_rng(seed)
    n, edges, cells = random_grid(rng, 8, 8, 0.1)
    dur = {}
    for u, v in sorted(edges):  # 1 to 3 steps, the same both ways
        dur[(u, v)] = dur[(v, u)] if (v, u) in dur else int(rng.integers(1, 4))
    edges = dur
    gap = np.abs(cells[:, None] - cells[None])
    diagonal = (gap[..., 0] == 1) & (gap[..., 1] == 1)
    prox = (np.where(diagonal, 0.5, 5.0), 1.0)  # diagonal neighbours are near
    starts, goals = pick(rng, n, 8)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="durative", proximity=prox)
    res = solve_pibt(inst)
    if res.status == "infeasible":
        assert "proximity radius" in res.message  # two starts or two goals diagonal neighbours
        return
    assert res.solved, res.message
    assert validate(inst, None, None, res.paths) == []


def test_solves_the_grid_crowd_prioritised_planning_gives_up_on():
    n = 8
    adj = open_grid(n)
    rng = np.random.default_rng(0)
    starts, goals = (rng.permutation(n * n)[:40].tolist() for _ in range(2))
    for time_model in ("unit", "durative"):
        crowd = MapfInstance(adj, starts, goals, time_model=time_model)
        assert solve_prioritized(crowd).status == "timeout"
        res = solve_pibt(crowd)
        assert res.status == "suboptimal", res.message
        assert validate(adj, starts, goals, res.paths, time_model=time_model) == []


def test_solves_a_buffer_like_crowd_prioritised_planning_gives_up_on():
    inst = buffer_like(2)
    assert solve_prioritized(inst, expansion_limit=2_500 * 30).status == "timeout"
    res = solve_pibt(inst, expansion_limit=10_000 * 30)
    assert res.status == "suboptimal", res.message
    assert validate(inst, None, None, res.paths) == []
    # the goals have no way out: every agent arrives there once, at the end of its path
    for i, p in enumerate(res.paths):
        assert [v for v, _ in p].count(inst.goals[i]) == 1


@pytest.mark.parametrize("seed", [0, 1, 3, 4, 5, 7])
def test_buffer_like_crowds_are_solved_and_valid(seed):
    inst = buffer_like(seed)
    res = solve_pibt(inst, expansion_limit=10_000 * 30)
    assert res.status == "suboptimal", res.message
    assert validate(inst, None, None, res.paths) == []


def test_an_agent_does_not_park_where_it_would_shut_another_out():
    # a corridor 0 - 1 - 2 - 3 - 4 - 5 (both ways) with a side pocket 7 at node 3; agent 0's goal
    # 6 (entered from 3, no way out) is near node 3, so once agent 0 is parked nobody passes 3.
    # Agent 0 starts in the pocket, two moves from its goal; agent 1 goes from 0 to 5 and needs
    # three moves to pass node 3: agent 0 must wait for it.
    adj = [[1], [0, 2], [1, 3], [2, 4, 6, 7], [3, 5], [4], [], [3]]
    near = np.full((8, 8), 5.0)
    near[6, 3] = near[3, 6] = 0.5
    inst = MapfInstance(adj, [7, 0], [6, 5], time_model="durative", proximity=(near, 1.0))
    res = solve_pibt(inst)
    assert res.status == "suboptimal", res.message
    assert validate(inst, None, None, res.paths) == []
    past = min(t for v, t in res.paths[1] if v == 4)  # agent 1 past node 3
    assert res.paths[0][-1][1] > past  # agent 0 parks only then


def test_same_input_same_plan():
    inst = buffer_like(4)
    a = solve_pibt(inst, expansion_limit=300_000)
    b = solve_pibt(inst, expansion_limit=300_000)
    assert a.status == b.status == "suboptimal"
    assert a.paths == b.paths and a.work == b.work
    crowd = MapfInstance(open_grid(8), *(np.random.default_rng(0).permutation(64)[:40].tolist() for _ in range(2)))
    assert solve_pibt(crowd, seed=3).paths == solve_pibt(crowd, seed=3).paths


def test_budget_and_stalls_end_in_timeout_with_a_message():
    inst = buffer_like(2)
    res = solve_pibt(inst, expansion_limit=500)
    assert res.status == "timeout" and res.paths is None
    assert "expansion limit of 500 reached" in res.message and "agents at their goals" in res.message
    assert res.work > 500
    res = solve_pibt(inst, time_limit=1e-9)
    assert res.status == "timeout" and "time limit" in res.message
    # a run with no new agent at its goal for 1 x 4 steps stalls; no restart allowed
    res = solve_pibt(buffer_like(4), stall_moves=1, restarts=0)
    assert res.status == "timeout" and "1 runs stalled" in res.message


def test_infeasible_and_bad_input():
    res = solve_pibt(MapfInstance([[1], [0], []], [0, 2], [1, 0]))
    assert res.status == "infeasible" and "agent 1" in res.message
    near = np.full((4, 4), 5.0)
    near[0, 1] = near[1, 0] = 0.5
    ring = [[1, 3], [0, 2], [1, 3], [2, 0]]
    res = solve_pibt(MapfInstance(ring, [0, 1], [2, 3], proximity=(near, 1.0)))
    assert res.status == "infeasible" and "starts of agents 0 and 1" in res.message
    res = solve_pibt(MapfInstance(ring, [2, 3], [0, 1], proximity=(near, 1.0)))
    assert res.status == "infeasible" and "goals of agents 0 and 1" in res.message
    empty = solve_pibt(MapfInstance(ring, [], []))
    assert empty.status == "optimal" and empty.paths == []
    inst = MapfInstance(ring, [0], [2])
    alone = solve_pibt(inst)
    assert alone.status == "optimal" and alone.soc == 2 and validate(inst, None, None, alone.paths) == []
    for kw, match in ((dict(seed=1.5), "seed"), (dict(patience=-1), "patience"), (dict(restarts=-1), "restarts"),
                      (dict(stall_moves=0), "stall_moves"), (dict(expansion_limit=0), "expansion_limit"),
                      (dict(time_limit=0), "time_limit")):
        with pytest.raises(ValueError, match=match):
            solve_pibt(inst, **kw)


def test_planner_steps_where_prioritised_planning_gives_up():
    pts = grid_points(12)
    starts, goals = _crossing_problem(24)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9)
    forced = planner.with_options(solver="pibt").plan(starts, goals)
    assert forced.solved and forced.solver == "pibt", forced.message
    assert _validate_plan(forced, 24, 0.9) == []
    assert forced.soc == sum(forced.arrival_times)
    # "auto": prioritised planning first; out of its budget (1 expansion per agent), the stepper
    starved = planner.with_options(prioritized_expansions_per_agent=1).plan(starts, goals)
    assert starved.solved and starved.solver == "pibt", starved.message
    assert "after prioritized: expansion limit of 24" in starved.message
    assert starved.cbs is not None and starved.cbs.paths == forced.cbs.paths
    # where prioritised planning succeeds, its plan stands
    plan = planner.plan(starts, goals)
    assert plan.solver == "prioritized" and plan.solved
