"""Safe-interval path planning and prioritised planning, against brute force on small graphs."""
import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid
from test_cbs_bruteforce import adjacency, pick, random_graph

from agents.search.mapf import MapfInstance, Proximity, validate
from agents.search.mapf.prioritized import initial_order, plan_in_order, release_order, solve_prioritized
from agents.search.mapf.sipp import FOREVER, IntervalTable, sipp


def random_proximity(rng, n, p_near=0.15):
    """A random symmetric 'near' relation as a distance matrix with radius 1."""
    d = np.full((n, n), 5.0)
    near = rng.random((n, n)) < p_near
    near = near | near.T
    d[near] = 0.5
    np.fill_diagonal(d, 0.0)
    return Proximity(d, 1.0), near


def blocked_steps(inst, paths, horizon):
    """Per step ``0..horizon``, the nodes another agent occupies or is near (an independent
    rendering of the occupancy rules), and the reserved unit-time moves."""
    near = inst.near_mat
    occ = [set() for _ in range(horizon + 1)]
    moves = set()
    for events in paths:
        timeline = []
        for (u, t0), (v, t1) in zip(events, events[1:]):
            here = {u} if (inst.unit or u == v) else {u, v}
            timeline.extend([here] * (t1 - t0))
            if inst.unit and u != v:
                moves.add((u, v, t0))
        while len(timeline) <= horizon:
            timeline.append({events[-1][0]})
        for t in range(horizon + 1):
            for x in timeline[t]:
                occ[t].add(x)
                if near is not None:
                    occ[t].update(np.flatnonzero(near[x]).tolist())
    return occ, moves


def brute_force_arrival(inst, agent, paths, horizon=60):
    """Earliest arrival of ``agent`` at its goal avoiding ``paths`` (then parked for good), by
    breadth-first search over ``(node, time)`` up to ``horizon``; ``None`` if none."""
    occ, moves = blocked_steps(inst, paths, horizon)
    last_blocked = {}
    for t in range(horizon + 1):
        for x in occ[t]:
            last_blocked[x] = t
    g = inst.goals[agent]
    s = inst.starts[agent]
    if s in occ[0]:
        return None
    reach = [set() for _ in range(horizon + 1)]
    reach[0].add(s)
    for t in range(horizon):
        for u in reach[t]:
            if u == g and last_blocked.get(g, -1) < t:
                return t
            for v, d in inst.succ_d[u]:
                d = 1 if (inst.unit or u == v) else d
                if t + d > horizon:
                    continue
                if inst.unit:
                    if v in occ[t + 1] or (v, u, t) in moves:
                        continue
                elif any(u in occ[k] or v in occ[k] for k in range(t, t + d)) or v in occ[t + d]:
                    continue
                reach[t + d].add(v)
    return None


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_sipp_is_earliest_arrival_against_brute_force(seed, time_model):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 11))
    edges = random_graph(rng, n, 0.2, max_dur=1 if time_model == "unit" else 3)
    prox, _ = random_proximity(rng, n, 0.1) if seed % 2 else (None, None)
    k = int(rng.integers(2, 5))
    starts, goals = pick(rng, n, k, crossing=seed % 3 == 0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model=time_model, proximity=prox)
    table = IntervalTable(inst)
    done = []
    for i in range(k - 1):
        p = sipp(inst, i, table)
        if p is None:
            return  # an earlier agent is stuck: nothing to compare for the last one
        table.reserve(i, p)
        done.append(p)
    expected = brute_force_arrival(inst, k - 1, done)
    got = sipp(inst, k - 1, table)
    if expected is None:
        assert got is None or got[-1][1] > 60
        return
    assert got is not None, (edges, starts, goals, done)
    assert got[-1][1] == expected
    assert validate(inst, None, None, done + [got]) == []


@pytest.mark.parametrize("seed", range(40))
def test_prioritized_plans_are_valid_and_not_below_optimal(seed):
    rng = np.random.default_rng(100 + seed)
    time_model = "unit" if seed % 2 else "durative"
    n = int(rng.integers(5, 9))
    edges = random_graph(rng, n, 0.25, max_dur=1 if time_model == "unit" else 2)
    prox, near = random_proximity(rng, n, 0.08) if seed % 4 == 1 else (None, None)
    starts, goals = pick(rng, n, int(rng.integers(2, 4)), crossing=seed % 3 == 0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model=time_model, proximity=prox)
    res = solve_prioritized(inst, start_hold=int(rng.integers(0, 4)))
    optimum = brute_force_soc(n, edges, starts, goals, unit=time_model == "unit",
                              near=None if near is None else near.tolist())
    if res.solved:
        assert validate(inst, None, None, res.paths) == []
        assert optimum is not None and res.soc >= optimum
        assert res.soc == sum(p[-1][1] for p in res.paths)
        assert res.lower_bound <= optimum
    else:
        assert res.status in ("timeout", "infeasible")
        if res.status == "infeasible":
            assert optimum is None


def test_interval_table_holds_and_releases():
    inst = MapfInstance([[1], [0, 2], [1]], [0, 2], [2, 0], time_model="unit")
    table = IntervalTable(inst)
    table.hold(1, 2, 5)
    assert table.safe(2) == [(6, FOREVER)] and table.holders(2) == {1} and table.holders(0) == set()
    table.reserve(0, [(0, 0), (1, 1), (1, 8), (2, 9)])
    assert table.safe(1) == [(0, 0), (9, FOREVER)]
    assert table.safe(2) == [(6, 8)]  # held to 5, then agent 0 parks there from 9
    table.release(1)
    assert table.safe(2) == [(0, 8)]


def test_prioritized_many_agents_on_a_grid_is_valid():
    rng = np.random.default_rng(3)
    n, edges, _ = random_grid(rng, 12, 12, 0.1)
    starts, goals = pick(rng, n, 30)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit")
    res = solve_prioritized(inst)
    assert res.solved, res.message
    assert validate(inst, None, None, res.paths) == []


def test_prioritized_reports_unreachable_goal_and_bad_options():
    inst = MapfInstance([[1], [0], []], [0, 2], [1, 0], time_model="unit")
    res = solve_prioritized(inst)
    assert res.status == "infeasible" and "agent 1" in res.message
    with pytest.raises(ValueError, match="restarts"):
        solve_prioritized(inst, restarts=-1)
    with pytest.raises(ValueError, match="expansion_limit"):
        solve_prioritized(inst, expansion_limit=0)
    with pytest.raises(ValueError, match="order"):
        solve_prioritized(MapfInstance([[1], [0]], [0], [1]), order=[1])


def test_prioritized_expansion_budget_is_reported_as_timeout():
    rng = np.random.default_rng(5)
    n, edges, _ = random_grid(rng, 10, 10, 0.0)
    starts, goals = pick(rng, n, 10)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit")
    res = solve_prioritized(inst, expansion_limit=20)
    assert res.status == "timeout" and "expansion limit of 20" in res.message
    assert res.work == 21


def test_initial_order_puts_an_agent_after_the_one_waiting_at_its_goal():
    # a path 0-1-2-3: agent 0 (farther) ends at 2, where agent 1 starts: agent 1 goes first
    inst = MapfInstance([[1], [0, 2], [1, 3], [2]], [0, 2], [2, 3], time_model="unit")
    assert initial_order(inst) == [1, 0]
    # on a cycle of such precedences the far-first order stays
    cyc = MapfInstance([[1], [0, 2], [1, 3], [2]], [0, 3], [3, 0], time_model="unit")
    assert initial_order(cyc) == [0, 1]


def test_an_agent_shut_in_by_a_waiting_agent_goes_after_it():
    # path 0-1-2-3 with a pocket 4 off node 2; agent 0 (0 -> 3) is planned first but agent 1
    # waits at 1 in its way until it is planned: agent 1 (1 -> 4) is planned first instead
    adj = [[1], [0, 2], [1, 3, 4], [2], [2]]
    inst = MapfInstance(adj, [0, 1], [3, 4], time_model="unit")
    paths, failed = plan_in_order(inst, [0, 1], [0])
    assert failed is None
    assert validate(inst, None, None, paths) == []


def test_initial_order_and_plan_in_order_report_the_failed_agent():
    # a corridor 0-1-2 where agent 1 waits at its goal 1 in the middle: agent 0 cannot pass
    inst = MapfInstance([[1], [0, 2], [1]], [0, 1], [2, 1], time_model="unit")
    assert initial_order(inst) == [0, 1]
    paths, failed = plan_in_order(inst, [1, 0], [0])
    assert paths is None and failed == 0


def test_gives_up_at_once_when_a_restart_would_repeat_the_last_attempt():
    # agent 1 starts on its goal, node 6, the only way into agent 0's goal (node 3): it has to
    # step aside and come back, which prioritised planning never plans (it plans each agent
    # once); a plan exists (the brute force's sum of costs is 6)
    n = 8
    edges = {(u, v): 1 for u, v in [(0, 2), (0, 5), (0, 6), (1, 2), (1, 4), (2, 0), (2, 1), (2, 4), (2, 7), (3, 6),
                                     (4, 1), (4, 2), (4, 6), (4, 7), (5, 0), (5, 7), (6, 0), (6, 3), (6, 4), (7, 2),
                                     (7, 4), (7, 5)]}
    starts, goals = [7, 6], [3, 6]
    assert brute_force_soc(n, edges, starts, goals) == 6
    adj = [[v for (u, v) in sorted(edges) if u == x] for x in range(n)]
    res = solve_prioritized(MapfInstance(adj, starts, goals), restarts=20, joint_check_states=0)
    # the release order plans agent 1 first (agent 0's way passes its start), then agent 0
    # fails; the far-first order plans agent 0 first, and it fails there too: moving it to the
    # front again would change nothing, so two attempts in all
    assert release_order(MapfInstance(adj, starts, goals)) == [1, 0]
    assert res.status == "timeout" and "repeat the last attempt" in res.message
    assert res.stats.orders == 2


def open_route(inst, agent, closed):
    """Whether ``agent`` can reach its goal along the graph's edges through nodes outside
    ``closed`` (breadth-first search; an independent rendering of the release rule)."""
    seen, todo = {inst.starts[agent]}, [inst.starts[agent]]
    while todo:
        u = todo.pop()
        if u == inst.goals[agent]:
            return True
        for v in inst.succ[u]:
            if v not in seen and (v not in closed or v == inst.goals[agent]):
                seen.add(v)
                todo.append(v)
    return False


def start_area(inst, agents):
    """The nodes at or near the starts of ``agents``."""
    out = set()
    for a in agents:
        out.add(inst.starts[a])
        if inst.near is not None:
            out.update(inst.near[inst.starts[a]])
    return out


@pytest.mark.parametrize("seed", range(40))
def test_release_order_against_brute_force(seed):
    # every agent released has a route, and a goal, clear of the starts of the agents after it;
    # the agents never released (the tail) have none while the tail's starts are there
    rng = np.random.default_rng(500 + seed)
    n = int(rng.integers(6, 11))
    edges = random_graph(rng, n, 0.15, directed=seed % 2 == 0)
    prox, _ = random_proximity(rng, n, 0.1) if seed % 3 else (None, None)
    starts, goals = pick(rng, n, int(rng.integers(2, 5)), crossing=seed % 4 == 0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit", proximity=prox)
    order = release_order(inst)
    assert sorted(order) == list(range(inst.n_agents)) and release_order(inst) == order
    k = inst.n_agents

    def clear(a, later):
        closed = start_area(inst, later)
        return inst.starts[a] not in closed and inst.goals[a] not in closed and open_route(inst, a, closed)

    # the longest prefix whose agents are all clear of the agents after them
    released = 0
    while released < k and clear(order[released], order[released + 1:]):
        released += 1
    tail = order[released:]
    for a in tail:  # with every agent before the tail gone, no tail agent is clear of the others
        assert not clear(a, [b for b in tail if b != a])
    # the tail keeps the far-first order
    assert tail == [a for a in initial_order(inst) if a in tail]


def test_release_order_plans_the_agents_in_the_way_first():
    # a path 0-1-2-3-4 with pockets 5 (off 1) and 6 (off 3); agent 0 goes 0 -> 4 (the farthest,
    # first in the far-first order) past agents 1 and 2 waiting at 1 and 3 for their pockets
    adj = [[1], [0, 2, 5], [1, 3], [2, 4, 6], [3], [1], [3]]
    inst = MapfInstance(adj, [0, 1, 3], [4, 5, 6], time_model="unit")
    assert initial_order(inst)[0] == 0
    assert release_order(inst) == [1, 2, 0]
    # planned first, agent 0 is shut in by agent 1, then by agent 2: put back behind each
    paths, failed = plan_in_order(inst, [0, 1, 2], [0], deferrals=1)
    assert paths is None and failed == 0
    paths, failed = plan_in_order(inst, [0, 1, 2], [0], deferrals=2)
    assert failed is None and validate(inst, None, None, paths) == []
    res = solve_prioritized(inst)
    assert res.solved and res.stats.orders == 1 and validate(inst, None, None, res.paths) == []
    assert solve_prioritized(inst).paths == res.paths
    with pytest.raises(ValueError, match="deferrals"):
        plan_in_order(inst, [0, 1, 2], [0], deferrals=-1)
