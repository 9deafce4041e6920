"""Large-neighbourhood repair: the conflict table against validate, the fewest-conflict search
against brute force, and repaired plans checked by validate on small graphs and grids."""
import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid
from test_cbs_bruteforce import adjacency, pick, random_graph
from test_prioritized import blocked_steps, brute_force_arrival, random_proximity

from agents.search.mapf import MapfInstance, Proximity, validate
from agents.search.mapf.conflict_table import ConflictTable, occupancy, soft_sipp
from agents.search.mapf.lns import direct_path, solve_lns
from agents.search.mapf.prioritized import solve_prioritized
from agents.search.mapf.sipp import FOREVER, IntervalTable, sipp


def random_walk(rng, inst, start, steps):
    """A timed path of random waits and moves from ``start`` (durations of the instance)."""
    u, t = start, 0
    events = [(u, 0)]
    for _ in range(steps):
        opts = inst.succ_d[u]
        v, d = opts[int(rng.integers(len(opts)))]
        d = 1 if (inst.unit or v == u) else d
        t += d
        u = v
        events.append((u, t))
    return events


def pair_conflicts(graph, paths, time_model, proximity):
    """Which pairs of agents validate reports in conflict (agent numbers from its messages)."""
    starts = [p[0][0] for p in paths]
    goals = [p[-1][0] for p in paths]
    out = set()
    for i in range(len(paths)):
        for j in range(i + 1, len(paths)):
            msgs = validate(graph, [starts[i], starts[j]], [goals[i], goals[j]], [paths[i], paths[j]],
                            time_model=time_model, proximity=proximity)
            if msgs:
                out.add((i, j))
    return out


# ---------------------------------------------------------------------- conflict table
@pytest.mark.parametrize("seed", range(40))
def test_conflict_table_finds_exactly_the_pairs_validate_reports(seed):
    rng = np.random.default_rng(seed)
    time_model = "unit" if seed % 2 else "durative"
    n = int(rng.integers(4, 9))
    edges = random_graph(rng, n, 0.3, max_dur=1 if time_model == "unit" else 3)
    prox, _ = random_proximity(rng, n, 0.15) if seed % 3 == 0 else (None, None)
    adj = adjacency(n, edges)
    inst = MapfInstance(adj, [0], [0], time_model=time_model, proximity=prox)
    k = int(rng.integers(2, 6))
    paths = [random_walk(rng, inst, int(rng.integers(n)), int(rng.integers(0, 6))) for _ in range(k)]
    expected = pair_conflicts(adj, paths, time_model, prox)
    table = ConflictTable(inst)
    for i, p in enumerate(paths):
        table.reserve(i, p)
    got = {(min(i, j), max(i, j)) for i in range(k) for j in table.conflicts(paths[i], i)}
    assert got == expected, (paths, edges)
    # removing a path removes its conflicts
    table.remove(0)
    assert table.conflicts(paths[0]) == {j for (i, j) in expected if i == 0}
    assert all(0 not in table.conflicts(paths[i], i) for i in range(1, k))


def test_conflict_table_hand_made_durative_edges_swaps_and_proximity():
    # a path 0 - 1 - 2 - 3 with durations 3 (0-1), 1 (1-2) and 2 (2-3)
    adj = [[(1, 3)], [(0, 3), (2, 1)], [(1, 1), (3, 2)], [(2, 2)]]
    inst = MapfInstance(adj, [0], [3], time_model="durative")
    table = ConflictTable(inst)
    table.reserve(7, [(0, 0), (1, 3)])  # on edge 0 -> 1 during steps 0..2, then at 1 for good
    assert table.segments(1) == ([0], [FOREVER], [frozenset({7})])
    assert table.segments(0) == ([0, 3], [2, FOREVER], [frozenset({7}), frozenset()])
    assert table.move_conflicts(2, 1, 0) == {7}  # arrives at 1 while agent 7 is on its way there
    assert table.move_conflicts(3, 2, 0) == set()
    assert table.conflicts([(0, 3)]) == set()  # parked at 0 from step 3: agent 7 has left
    assert table.conflicts([(0, 2)]) == {7}
    with pytest.raises(ValueError, match="already has a path"):
        table.reserve(7, [(2, 0)])
    with pytest.raises(ValueError, match="no edge"):
        table.move_conflicts(0, 3, 0)
    # unit time: a swap along an edge is a conflict, following one step behind is not
    unit = MapfInstance([[1], [0, 2], [1]], [0], [2], time_model="unit")
    table = ConflictTable(unit)
    table.reserve(1, [(0, 0), (1, 1), (2, 2)])
    assert table.conflicts([(1, 0), (0, 1)]) == {1}  # swap 0 <-> 1 at t = 0
    assert table.move_conflicts(1, 0, 0) == {1}
    assert table.conflicts([(1, 5), (0, 6)]) == set()
    assert table.conflicts([(1, 0), (1, 1)]) == {1}
    # proximity: nodes 0 and 2 are near each other
    d = np.full((3, 3), 5.0)
    d[0, 2] = d[2, 0] = 0.5
    near = MapfInstance([[1], [0, 2], [1]], [0], [2], time_model="unit", proximity=Proximity(d, 1.0))
    table = ConflictTable(near)
    table.reserve(3, [(2, 0)])  # parked at 2
    assert table.conflicts([(0, 0), (1, 1)]) == {3}  # at 0 (near 2) at t = 0
    assert table.conflicts([(1, 0)]) == set()
    assert table.agents_at(0) == {3} and table.agents_at(1) == set()


def test_occupancy_of_a_durative_path():
    spans, moves = occupancy([(0, 0), (0, 2), (1, 5)], unit=False)
    assert spans == [(0, 0, 1), (0, 2, 4), (1, 2, 4), (1, 5, FOREVER)] and moves == []
    spans, moves = occupancy([(0, 0), (1, 1), (1, 3)], unit=True)
    assert spans == [(0, 0, 0), (1, 1, 2), (1, 3, FOREVER)] and moves == [(0, 1, 0)]


# ---------------------------------------------------------------------- fewest-conflict search
def brute_force_fewest(inst, agent, table, horizon=40):
    """Fewest agents of ``table`` that any path of ``agent`` (parked at its goal from its last
    arrival) conflicts with, and the earliest arrival with that many: breadth first over
    ``(node, time, agents met)`` up to ``horizon``, with an independent rendering of what each
    agent occupies (:func:`blocked_steps`, per agent). ``None`` if the goal is never reached."""
    per_agent = {}
    for a, p in table.paths.items():
        occ, moves = blocked_steps(inst, [p], horizon + 5)
        per_agent[a] = (occ, moves)

    def met_at(x, t):
        return frozenset(a for a, (occ, _) in per_agent.items() if x in occ[t])

    def met_after(x, t):  # parked at x from t on
        return frozenset(a for a, (occ, _) in per_agent.items() if any(x in occ[k] for k in range(t, horizon + 5)))

    s, g = inst.starts[agent], inst.goals[agent]
    layer = {(s, met_at(s, 0))}
    arrivals = {}  # time -> fewest agents met by a path parked at g from then
    states = {0: layer}
    for t in range(horizon):
        for u, met in states.get(t, ()):
            if u == g:
                c = len(met | met_after(g, t))
                arrivals[t] = min(arrivals.get(t, c), c)
            for v, d in inst.succ_d[u]:
                d = 1 if (inst.unit or u == v) else d
                if t + d > horizon:
                    continue
                new = set(met)
                if inst.unit:
                    new |= met_at(v, t + 1)
                    new |= {a for a, (_, moves) in per_agent.items() if (v, u, t) in moves}
                else:
                    for k in range(t, t + d):
                        new |= met_at(u, k) | met_at(v, k)
                    new |= met_at(v, t + d)
                states.setdefault(t + d, set()).add((v, frozenset(new)))
    if not arrivals:
        return None
    fewest = min(arrivals.values())
    return fewest, min(t for t, c in arrivals.items() if c == fewest)


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_soft_sipp_against_brute_force(seed, time_model):
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(5, 9))
    edges = random_graph(rng, n, 0.2, max_dur=1 if time_model == "unit" else 3)
    prox, _ = random_proximity(rng, n, 0.1) if seed % 2 else (None, None)
    k = int(rng.integers(3, 6))
    starts, goals = pick(rng, n, k, crossing=seed % 3 == 0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model=time_model, proximity=prox)
    table = ConflictTable(inst)
    hard = IntervalTable(inst)
    for i in range(k - 1):  # the others on their shortest paths, conflicts or not
        p = direct_path(inst, i)
        table.reserve(i, p)
        hard.reserve(i, p)
    agent = k - 1
    got = soft_sipp(inst, agent, table)
    assert got is not None
    assert validate(inst, [starts[agent]], [goals[agent]], [got]) == []  # a path of the graph
    met = table.conflicts(got, agent)
    free = brute_force_arrival(inst, agent, list(table.paths.values()))
    if free is not None:  # a conflict-free path exists: found, and as early as any
        assert met == set() and got[-1][1] == free
        p = sipp(inst, agent, hard)
        assert p is not None and p[-1][1] == free
    else:
        assert met
    best = brute_force_fewest(inst, agent, table)
    if best is not None and got[-1][1] <= 40:
        # never fewer than the fewest possible; found the fewest on these instances
        assert len(met) == best[0], (got, met, best)


def test_soft_sipp_goes_through_the_fewest_agents():
    # two routes from 0 to 5: 0-1-2-5 passes agents parked at 1 and 2, 0-3-4-5 one parked at 4
    adj = [[1, 3], [0, 2], [1, 5], [0, 4], [3, 5], [2, 4]]
    inst = MapfInstance(adj, [0, 1, 2, 4], [5, 1, 2, 4], time_model="unit")
    table = ConflictTable(inst)
    for a in (1, 2, 3):
        table.reserve(a, [(inst.starts[a], 0)])
    p = soft_sipp(inst, 0, table)
    assert [u for u, _ in p] == [0, 3, 4, 5] and table.conflicts(p, 0) == {3}
    # a tiny expansion limit: no path; past the budget: BudgetExceeded
    assert soft_sipp(inst, 0, table, limit=1) is None
    from agents.search.mapf.sipp import BudgetExceeded
    with pytest.raises(BudgetExceeded):
        soft_sipp(inst, 0, table, budget=1, counter=[0])


# ---------------------------------------------------------------------- the repair
@pytest.mark.parametrize("seed", range(30))
def test_repair_plans_are_valid_and_not_below_optimal(seed):
    rng = np.random.default_rng(200 + seed)
    time_model = "unit" if seed % 2 else "durative"
    n = int(rng.integers(5, 9))
    edges = random_graph(rng, n, 0.25, max_dur=1 if time_model == "unit" else 2)
    prox, near = random_proximity(rng, n, 0.08) if seed % 4 == 1 else (None, None)
    starts, goals = pick(rng, n, int(rng.integers(2, 4)), crossing=seed % 3 == 0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model=time_model, proximity=prox)
    res = solve_lns(inst, expansion_limit=20_000, joint_check_states=0)
    check_against_brute_force(inst, n, edges, near, res)


def check_against_brute_force(inst, n, edges, near, res):
    """A plan is valid and costs no less than the optimum; no plan only where the budget ran out."""
    optimum = brute_force_soc(n, edges, inst.starts, inst.goals, unit=inst.unit,
                              near=None if near is None else near.tolist())
    if res.solved:
        assert validate(inst, None, None, res.paths) == []
        assert optimum is not None and res.soc >= optimum and res.lower_bound <= optimum
        assert res.soc == sum(p[-1][1] for p in res.paths)
    else:
        assert res.status == "timeout" and "expansion limit of 20000" in res.message
    return optimum


def test_repair_on_crowded_tiny_graphs_against_brute_force_and_prioritised_planning():
    # 3-4 agents on 5-7 nodes: most instances have conflicts to repair, some have no plan
    solved = {"lns": 0, "prioritized": 0}
    repaired = 0
    for seed in range(40):
        rng = np.random.default_rng(300 + seed)
        time_model = "unit" if seed % 2 else "durative"
        n = int(rng.integers(5, 8))
        edges = random_graph(rng, n, 0.2, max_dur=1 if time_model == "unit" else 2)
        prox, near = random_proximity(rng, n, 0.08) if seed % 4 == 1 else (None, None)
        starts, goals = pick(rng, n, int(rng.integers(3, 5)), crossing=seed % 3 == 0)
        inst = MapfInstance(adjacency(n, edges), starts, goals, time_model=time_model, proximity=prox)
        res = solve_lns(inst, expansion_limit=20_000)
        if res.status == "infeasible":  # the joint check before the search
            assert brute_force_soc(n, edges, starts, goals, unit=inst.unit,
                                   near=None if near is None else near.tolist()) is None
            continue
        optimum = check_against_brute_force(inst, n, edges, near, res)
        if optimum is None:  # impossible, and not found so by the joint check: the budget ends
            assert res.status == "timeout"
        solved["lns"] += res.solved
        solved["prioritized"] += solve_prioritized(inst).solved
        repaired += res.solved and res.stats.initial_conflicts > 0
    assert repaired >= 3  # plans whose first version had conflicts
    assert solved["lns"] > solved["prioritized"], solved


@pytest.mark.parametrize("seed", range(6))
def test_repair_solves_crowded_grids_where_prioritised_planning_fails(seed):
    rng = np.random.default_rng(seed)
    n, edges, _ = random_grid(rng, 9, 9, 0.15)
    adj = adjacency(n, edges)
    reach = MapfInstance(adj, [0], [0]).dist_to(0)
    free = [v for v in range(n) if reach[v] < 1 << 30 and adj[v]]  # the part node 0 is in
    starts = [int(x) for x in rng.choice(free, 28, replace=False)]
    goals = [int(x) for x in rng.choice(free, 28, replace=False)]
    inst = MapfInstance(adj, starts, goals, time_model="unit")
    res = solve_lns(inst, expansion_limit=300_000, seed=seed)
    assert res.solved, res.message
    assert validate(inst, None, None, res.paths) == []


def test_repair_succeeds_where_an_agent_must_step_aside():
    # agent 1 starts on its goal, node 6, the only way into agent 0's goal (node 3): prioritised
    # planning never plans it to step aside and come back; the repair does (brute force: 6)
    n = 8
    edges = {(u, v): 1 for u, v in [(0, 2), (0, 5), (0, 6), (1, 2), (1, 4), (2, 0), (2, 1), (2, 4), (2, 7), (3, 6),
                                     (4, 1), (4, 2), (4, 6), (4, 7), (5, 0), (5, 7), (6, 0), (6, 3), (6, 4), (7, 2),
                                     (7, 4), (7, 5)]}
    inst = MapfInstance(adjacency(n, edges), [7, 6], [3, 6])
    assert not solve_prioritized(inst, joint_check_states=0).solved
    res = solve_lns(inst, joint_check_states=0)
    assert res.solved and validate(inst, None, None, res.paths) == []
    assert res.soc >= brute_force_soc(n, edges, [7, 6], [3, 6]) == 6


def crowded_grid(k=40, seed=1):
    rng = np.random.default_rng(seed)
    n, edges, _ = random_grid(rng, 10, 10, 0.0)
    starts, goals = pick(rng, n, k)
    return MapfInstance(adjacency(n, edges), starts, goals, time_model="durative")


def test_repair_is_deterministic_for_a_seed_and_reports_its_budget():
    inst = crowded_grid()
    a = solve_lns(inst, seed=3)
    b = solve_lns(inst, seed=3)
    assert a.solved and a.paths == b.paths and a.work == b.work
    assert validate(inst, None, None, a.paths) == []
    tiny = solve_lns(inst, expansion_limit=50)
    assert tiny.status == "timeout" and "expansion limit of 50 reached" in tiny.message
    assert tiny.work == 51


def test_repair_reports_infeasible_and_refuses_bad_options():
    inst = MapfInstance([[1], [0], []], [0, 2], [1, 0], time_model="unit")
    res = solve_lns(inst)
    assert res.status == "infeasible" and "agent 1" in res.message
    ring = [[(u - 1) % 5, (u + 1) % 5] for u in range(5)]
    res = solve_lns(MapfInstance(ring, [0, 1, 2, 3, 4], [1, 0, 2, 3, 4]))
    assert res.status == "infeasible" and res.work == 0
    ok = MapfInstance([[1], [0]], [0], [1])
    for kw, word in [(dict(seed=1.5), "seed"), (dict(seed=True), "seed"),
                     (dict(neighborhood_size=0), "neighborhood_size"), (dict(call_limit=0), "call_limit"),
                     (dict(expansion_limit=0), "expansion_limit"), (dict(time_limit=0), "time_limit"),
                     (dict(start_hold=-1), "start_hold"), (dict(joint_check_states=-1), "joint_check_states"),
                     (dict(order=[1]), "order")]:
        with pytest.raises(ValueError, match=word):
            solve_lns(ok, **kw)


# ---------------------------------------------------------------------- the planner
def test_planner_repair_solver_and_auto_fallback():
    from test_planner import _crossing_problem, _validate_plan, euclid_pairwise, grid_points, make_planner

    pts = grid_points(12)
    starts, goals = _crossing_problem(24)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9, solver="lns", repair_seed=2)
    plan = planner.plan(starts, goals)
    assert plan.solved and plan.solver == "lns", plan.message
    assert _validate_plan(plan, 24, 0.9) == []
    assert planner.with_options(solver="auto").solver_config.seed == 2
    # ECBS out of its budget: "auto" repairs
    starved = planner.with_options(solver="auto", expansion_limit=1, fallback_suboptimality=None)
    plan = starved.plan(starts[:12], goals[:12])
    assert plan.solved and plan.solver == "lns" and "after cbs" in plan.message, plan.message
    assert _validate_plan(plan, 12, 0.9) == []
    # prioritised planning out of its budget (above 20 agents): "auto" steps (no repair)
    plan = planner.with_options(solver="auto", prioritized_expansions_per_agent=1).plan(starts, goals)
    assert plan.solved and plan.solver == "pibt" and "after prioritized" in plan.message, plan.message
    assert _validate_plan(plan, 24, 0.9) == []
    # few agents: "auto" is CBS / ECBS as before, with the same plan
    auto = planner.with_options(solver="auto")
    few = auto.plan(starts[:4], goals[:4])
    cbs = auto.with_options(solver="cbs").plan(starts[:4], goals[:4])
    assert few.solver == "cbs" and few.cbs.paths == cbs.cbs.paths
