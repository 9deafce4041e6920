"""BufferPlanner: CBS over a graph of observations with stand-in (exact) distance and cost."""
import numpy as np
import pytest

from agents.search.execution.controller import AgentPlan
from agents.search.mapf import Proximity, validate
from agents.search.planner import BufferPlanner
from agents.search.waypoints import direct_plans, waypoints_from_paths


def euclid_pairwise(hot=None, hot_radius=0.0, hot_cost=10.0):
    """Distance = Euclidean length (>= 1); cost = ``hot_cost`` per unit inside a disc around ``hot``."""

    def pairwise(a, b):
        a = np.asarray(a, float)[:, None, :]
        b = np.asarray(b, float)[None, :, :]
        length = np.linalg.norm(b - a, axis=-1)
        cost = np.zeros_like(length)
        if hot is not None:
            s = np.linspace(0, 1, 11)[:, None, None, None]
            pts = a[None] + s * (b - a)[None]
            inside = np.linalg.norm(pts - np.asarray(hot), axis=-1) < hot_radius
            cost = hot_cost * inside.mean(axis=0) * length
        return np.maximum(length, 1.0), cost

    return pairwise


def grid_points(n=7, spacing=1.0):
    xs = np.arange(n) * spacing
    gx, gy = np.meshgrid(xs, xs)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def make_planner(points, pairwise, **kw):
    D, C = pairwise(points, points)
    return BufferPlanner(points, D, C, pairwise).with_options(**kw)


def test_waypoints_from_paths_hand_computed():
    # waits at node 5 (times 0..2), moves to 7 (arrives 4), leaves at 4, goal 9 at 6
    paths = [[(5, 0), (5, 1), (5, 2), (7, 4), (9, 6)], [(1, 0), (2, 1), (2, 2), (2, 3), (3, 4)]]
    nodes, depart, node_arrive, arrive = waypoints_from_paths(paths)
    assert nodes == [[5, 7], [1, 2]]
    assert depart == [[2, 4], [0, 3]]
    assert node_arrive == [[0, 4], [0, 1]]
    assert arrive == [6, 4]


def test_two_agents_swap_plan_is_valid_and_timed():
    pts = grid_points(6)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=1.2, suboptimality=1.0)
    starts = np.array([[0.0, 2.5], [5.0, 2.5]])
    goals = starts[::-1].copy()
    plan = planner.plan(starts, goals)
    assert plan.status == "optimal"
    res = plan.cbs
    dur = plan.problem.graph.distance.copy()
    dur.data = np.maximum(np.ceil(dur.data - 1e-9), 1.0)
    n = len(pts)
    prox = Proximity(plan.problem.D, planner.graph.proximity_radius)
    assert validate(dur, [n, n + 1], [n + 2, n + 3], res.paths, time_model="durative", proximity=prox) == []
    # both agents cross the grid: each arrival is at least the straight-line length in steps
    assert min(plan.arrival_times) >= 5
    # the controller plans start at the start observation and carry the departure times
    plans = plan.agent_plans()
    assert set(plans) == {"agent_0", "agent_1"}
    p0 = plans["agent_0"]
    assert isinstance(p0, AgentPlan)
    np.testing.assert_allclose(p0.waypoints[0], starts[0])
    assert len(p0.depart_times) == len(p0.waypoints)
    assert list(p0.depart_times) == sorted(p0.depart_times)


def test_cost_cutoff_routes_around_a_costly_region():
    pts = grid_points(9)
    pw = euclid_pairwise(hot=(4.0, 4.0), hot_radius=2.5)
    start, goal = np.array([[0.0, 4.0]]), np.array([[8.0, 4.0]])
    plain = make_planner(pts, pw, d_max=2.5).plan(start, goal)
    safe_planner = make_planner(pts, pw, d_max=2.5, c_max=0.5)
    safe = safe_planner.plan(start, goal)
    assert plain.solved and safe.solved
    assert safe.predicted_cost[0] < plain.predicted_cost[0]
    assert safe.predicted_cost[0] == pytest.approx(0.0, abs=1e-6)
    assert safe.arrival_times[0] > plain.arrival_times[0]  # the detour is longer
    # no visited node lies inside the costly disc
    visited = safe.waypoint_observations(0)
    assert (np.linalg.norm(visited - [4.0, 4.0], axis=1) >= 2.5).all()


def test_cost_cutoff_is_relaxed_until_every_agent_has_a_path():
    pts = grid_points(5)
    pw = euclid_pairwise(hot=(2.0, 2.0), hot_radius=10.0)  # everything is costly
    start, goal = np.array([[0.0, 0.0]]), np.array([[4.0, 4.0]])
    plan = make_planner(pts, pw, d_max=1.6, c_max=0.01).plan(start, goal)
    assert plan.solved and plan.c_max > 0.01
    strict = make_planner(pts, pw, d_max=1.6, c_max=0.01, relax_cost=False).plan(start, goal)
    assert strict.status == "infeasible" and not strict.solved
    assert "no path" in strict.message
    with pytest.raises(ValueError, match="infeasible"):
        strict.agent_plans()


def test_a_costly_stretch_many_edges_wide_is_relaxed_across():
    """Nodes on a line, neighbours linked; six costly edges in a row between start and goal. Doubling the
    cut-off widens the regions by one edge a round: it passes the costliest edge after four rounds, and the
    regions go on growing at that cut-off until they meet."""
    from agents.search.graph.edges import EdgeList, problem_edges
    from agents.search.graph.pruning import relax_cost_locally

    x = np.r_[np.arange(10.0), -1.0, 10.0]  # buffer nodes 0..9, the start at -1, the goal at 10
    D = np.abs(x[:, None] - x[None, :])
    mid = (x >= 2) & (x <= 8)
    C = np.where(mid[:, None] & mid[None, :], 10.0, 0.5)  # the edges among nodes 2..8 cost 10
    edges = problem_edges(EdgeList.short(D[:10, :10], C[:10, :10], 1.5), D, C, 10, 1.5)
    keep = edges.c < 1.0
    ok, c = relax_cost_locally(keep, edges, 10, 1.0)
    assert ok.tolist() == [True] and c == 16.0
    crossing = edges.dense(keep)
    assert all(crossing[i, i + 1] for i in range(9)) and crossing[10, 0] and crossing[9, 11]
    ok, c = relax_cost_locally(edges.c < 1.0, edges, 10, 1.0, relax=False)
    assert ok.tolist() == [False] and c == 1.0


def test_risk_budget_bounds_the_route_cost():
    pts = grid_points(9)
    pw = euclid_pairwise(hot=(4.0, 4.0), hot_radius=2.5)
    start, goal = np.array([[0.0, 4.0]]), np.array([[8.0, 4.0]])
    planner = make_planner(pts, pw, d_max=2.5)
    free = planner.plan(start, goal)
    bounded = planner.plan(start, goal, budget=1.0)
    assert free.predicted_cost[0] > 1.0
    assert bounded.solved and bounded.predicted_cost[0] <= 1.0 + 1e-9


def test_bad_inputs_are_named():
    pts = grid_points(3)
    pw = euclid_pairwise()
    D, C = pw(pts, pts)
    with pytest.raises(ValueError, match="D must have shape"):
        BufferPlanner(pts, D[:-1], C, pw)
    bad = D.copy()
    bad[0, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        BufferPlanner(pts, bad, C, pw)
    planner = BufferPlanner(pts, D, C, pw)
    with pytest.raises(ValueError, match="NaN"):
        planner.plan(np.array([[np.nan, 0.0]]), np.array([[1.0, 1.0]]))
    with pytest.raises(ValueError, match="starts"):
        planner.plan(np.zeros((2, 2)), np.zeros((1, 2)))


def test_direct_plans_have_no_waypoints():
    goals = np.array([[0.1, 0.2], [0.3, 0.4]])
    plans = direct_plans(goals, ["a", "b"])
    assert len(plans["a"].waypoints) == 0
    np.testing.assert_allclose(plans["b"].goal, goals[1])


def test_agents_starting_side_by_side_can_be_planned():
    pts = grid_points(6)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=1.5)
    starts = np.array([[0.0, 0.0], [1.0, 0.0]])  # closer than the proximity radius
    goals = np.array([[5.0, 5.0], [5.0, 4.0]])  # so are the goals
    plan = planner.plan(starts, goals)
    assert plan.solved, plan.message
    # on the way, the agents never come closer than the radius
    seq = plan.cbs.node_sequences(pad=True)
    D = plan.problem.D
    n = len(pts)
    for t in range(1, min(len(seq[0]), len(seq[1])) - 1):
        u, v = seq[0][t], seq[1][t]
        if {u, v} <= {n, n + 1} or {u, v} <= {n + 2, n + 3}:
            continue
        assert min(D[u, v], D[v, u]) >= 1.5


def test_excluded_nodes_are_never_used():
    """A replanning agent can forbid the nodes it failed to reach: the plan goes around them,
    and forbidding every way through leaves the agent without a plan."""
    pts = grid_points(7)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=None, suboptimality=1.0)
    start, goal = np.array([[0.0, 3.0]]), np.array([[6.0, 3.0]])
    free = planner.plan(start, goal)
    row = [i for i, p in enumerate(pts) if p[1] == 3.0 and 0 < p[0] < 6]
    assert set(row) <= set(free.nodes[0])  # the straight row is the shortest way
    wall = [i for i, p in enumerate(pts) if p[0] == 3.0 and p[1] >= 2.0]
    around = planner.plan(start, goal, exclude=wall)
    assert around.solved and not set(wall) & set(around.nodes[0])
    assert min(pts[i][1] for i in around.nodes[0] if i < len(pts)) <= 1.0  # went below the wall
    assert around.soc > free.soc
    blocked = planner.plan(start, goal, exclude=[i for i, p in enumerate(pts) if p[0] == 3.0])
    assert blocked.status == "infeasible"
    with pytest.raises(ValueError, match="exclude must hold buffer node ids"):
        planner.plan(start, goal, exclude=[len(pts)])


def test_detached_nodes_are_not_linked_to_the_start_but_routes_may_pass_them():
    """A replanning agent that failed to reach a node from where it stood (the critic took its place for one
    near that node) may not link its start to it again; a route through it from other nodes is kept."""
    pts = grid_points(7)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=None, suboptimality=1.0)
    start, goal = np.array([[0.0, 3.0]]), np.array([[6.0, 3.0]])
    first = planner.plan(start, goal).nodes[0][1]
    plan = planner.plan(start, goal, detached=[first])
    assert plan.solved and plan.nodes[0][1] != first  # the start links to another node
    problem = planner.problem_graph(start, goal, detached=[first])
    n, s = len(pts), problem.start_ids[0]
    linked = problem.graph.distance[s].indices
    assert len(linked) and first not in linked.tolist()
    into_first = problem.graph.distance[:n, first].nonzero()[0]
    assert len(into_first) and np.allclose(problem.graph.distance[:n, :n].toarray(), planner.problem_graph(
        start, goal).graph.distance[:n, :n].toarray())  # between buffer nodes the graph is unchanged
    # nodes beside the goal no longer linked to it: the route reaches it from another node
    last = planner.plan(start, goal).nodes[0][-1]
    other = planner.plan(start, goal, goal_detached=[last])
    assert other.solved and other.nodes[0][-1] != last
    g = planner.problem_graph(start, goal, goal_detached=[last])
    assert g.graph.distance[last, g.goal_ids[0]] == 0 and g.graph.distance[:n, g.goal_ids[0]].nnz
    with pytest.raises(ValueError, match="detached must hold buffer node ids"):
        planner.plan(start, goal, detached=[-1])
    with pytest.raises(ValueError, match="goal_detached must hold buffer node ids"):
        planner.plan(start, goal, goal_detached=[n])


@pytest.mark.parametrize("time_model", ["durative", "unit"])
def test_a_single_agent_gets_the_path_cbs_would_give(time_model):
    pts = grid_points(6)
    planner = make_planner(pts, euclid_pairwise(hot=(2.5, 2.5), hot_radius=1.2), d_max=2.5, c_max=0.5,
                           proximity_radius=1.2, suboptimality=1.0, time_model=time_model)
    start, goal = np.array([[0.0, 0.0]]), np.array([[5.0, 5.0]])
    plan = planner.plan(start, goal)
    assert plan.status == "optimal" and plan.cbs.message.startswith("a single agent")
    dur = plan.problem.graph.distance.copy()
    dur.data = np.maximum(np.ceil(dur.data - 1e-9), 1.0) if time_model == "durative" else np.ones_like(dur.data)
    n = len(pts)
    from agents.search.mapf import solve_cbs

    ref = solve_cbs(dur, [n], [n + 1], time_model=time_model, suboptimality=1.0)
    assert plan.soc == ref.soc
    assert validate(dur, [n], [n + 1], plan.cbs.paths, time_model=time_model) == []


def _crossing_problem(k, n=12):
    """``k`` agents on an ``n x n`` grid of points, from the left columns to the right ones."""
    rows = np.arange(k) % n
    cols = np.arange(k) // n
    starts = np.stack([cols * 1.0, rows * 1.0], axis=1) + 0.25
    goals = np.stack([(n - 1 - cols) * 1.0, rows[::-1] * 1.0], axis=1) + 0.25
    return starts, goals


def _validate_plan(plan, k, radius):
    n = len(plan.problem.observations) - 2 * k
    dur = plan.problem.graph.distance.copy()
    dur.data = np.maximum(np.ceil(dur.data - 1e-9), 1.0)
    P = plan.problem.D.copy()
    for lo in (n, n + k):
        P[lo:lo + k, lo:lo + k] = np.inf
    return validate(dur, list(range(n, n + k)), list(range(n + k, n + 2 * k)), plan.cbs.paths,
                    time_model="durative", proximity=Proximity(P, radius))


def test_auto_solver_picks_prioritized_planning_for_many_agents():
    pts = grid_points(12)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9)
    starts, goals = _crossing_problem(24)
    plan = planner.plan(starts, goals)
    assert plan.solved and plan.solver == "prioritized", plan.message
    assert _validate_plan(plan, 24, 0.9) == []
    assert plan.soc == sum(plan.arrival_times)
    few = planner.plan(starts[:3], goals[:3])
    assert few.solver == "cbs" and few.status in ("optimal", "suboptimal")
    forced = planner.with_options(solver="prioritized").plan(starts[:3], goals[:3])
    assert forced.solver == "prioritized" and _validate_plan(forced, 3, 0.9) == []
    assert forced.soc >= planner.with_options(suboptimality=1.0).plan(starts[:3], goals[:3]).soc


def test_planner_budget_is_counted_in_expansions():
    pts = grid_points(12)
    starts, goals = _crossing_problem(24)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9, expansion_limit=30,
                           prioritized_expansions_per_agent=1, repair_expansions_per_agent=2,
                           stepper_expansions_per_agent=3, fallback_suboptimality=None)
    plan = planner.plan(starts, goals)
    # prioritised planning runs out of 1 expansion per agent, then the stepper of 3 per agent
    # (no repair behind it)
    assert plan.status == "timeout" and plan.solver == "pibt", plan.message
    assert "expansion limit of 72" in plan.message and "after prioritized: expansion limit of 24" in plan.message
    # ECBS runs out of its 30 expansions, then the repair of 2 per agent
    plan = planner.plan(starts[:5], goals[:5])
    assert plan.status == "timeout" and plan.solver == "lns", plan.message
    assert "expansion limit of 30" in plan.message and "expansion limit of 10" in plan.message
    with pytest.raises(ValueError, match="solver"):
        make_planner(pts, euclid_pairwise(), solver="nope")
    with pytest.raises(ValueError, match="expansion_limit"):
        make_planner(pts, euclid_pairwise(), expansion_limit=0)
    with pytest.raises(ValueError, match="prioritized_expansions_per_agent"):
        make_planner(pts, euclid_pairwise(), prioritized_expansions_per_agent=2.5)
    with pytest.raises(ValueError, match="repair_expansions_per_agent"):
        make_planner(pts, euclid_pairwise(), repair_expansions_per_agent=0)
    with pytest.raises(ValueError, match="stepper_expansions_per_agent"):
        make_planner(pts, euclid_pairwise(), stepper_expansions_per_agent=0)
    with pytest.raises(ValueError, match="repair_seed"):
        make_planner(pts, euclid_pairwise(), repair_seed=1.5)


def band_pairwise(band=(2.6, 3.4), gap_y=5.5, base=0.5, extra=3.0):
    """Cost ``base`` per unit everywhere, ``extra`` more per unit inside a vertical band that is open
    only above ``gap_y``: a short crossing of it costs more than ``c_max``, the way round is long."""

    def pairwise(a, b):
        a = np.asarray(a, float)[:, None, :]
        b = np.asarray(b, float)[None, :, :]
        length = np.linalg.norm(b - a, axis=-1)
        s = np.linspace(0, 1, 11)[:, None, None, None]
        pts = a[None] + s * (b - a)[None]
        inside = (pts[..., 0] > band[0]) & (pts[..., 0] < band[1]) & (pts[..., 1] < gap_y)
        return np.maximum(length, 1.0), (base + extra * inside.mean(axis=0)) * length

    return pairwise


def test_the_cost_cutoff_never_sends_an_agent_the_long_way_round_to_a_far_higher_predicted_cost():
    gx, gy = np.meshgrid(np.arange(7.0), np.arange(13.0))
    pts, pw = np.stack([gx.ravel(), gy.ravel()], axis=1), band_pairwise(gap_y=11.5)
    start, goal = np.array([[0.0, 0.0]]), np.array([[6.0, 0.0]])
    plain = make_planner(pts, pw, d_max=2.5).plan(start, goal)
    unguarded = make_planner(pts, pw, d_max=2.5, c_max=1.0, cost_guard=None).plan(start, goal)
    guarded = make_planner(pts, pw, d_max=2.5, c_max=1.0).plan(start, goal)
    # the cut-off alone leaves only the way over the top of the band: over twice as costly
    assert unguarded.solved and unguarded.predicted_cost[0] > 2.0 * plain.predicted_cost[0]
    assert unguarded.waypoint_observations(0)[:, 1].max() >= 12.0
    # guarded, the straight route is admitted: no costlier than the plain search's
    assert guarded.solved and guarded.predicted_cost[0] <= plain.predicted_cost[0] + 1e-9
    assert guarded.waypoint_observations(0)[:, 1].max() < 2.0
    # a detour within the factor is kept (a shorter band: 1.4 times the plain route's cost)
    short_way_round = band_pairwise(gap_y=5.5)
    a = make_planner(pts, short_way_round, d_max=2.5, c_max=1.0).plan(start, goal)
    b = make_planner(pts, short_way_round, d_max=2.5, c_max=1.0, cost_guard=None).plan(start, goal)
    assert a.nodes == b.nodes and a.waypoint_observations(0)[:, 1].max() >= 6.0
    # and a factor of 1 admits it
    c = make_planner(pts, short_way_round, d_max=2.5, c_max=1.0, cost_guard=1.0).plan(start, goal)
    assert c.waypoint_observations(0)[:, 1].max() < 2.0
    # so does ``detour``: that detour is also over 1.5 times as long, and longer and costlier buys nothing
    d = make_planner(pts, short_way_round, d_max=2.5, c_max=1.0, detour=1.5)
    assert d.graph.detour == 1.5 and d.with_options(c_max=2.0).graph.detour == 1.5
    assert d.plan(start, goal).waypoint_observations(0)[:, 1].max() < 2.0
    with pytest.raises(ValueError, match="detour"):
        make_planner(pts, pw, detour=0.9)
    with pytest.raises(ValueError, match="cost_guard"):
        make_planner(pts, pw, cost_guard=0.5)


def admit(keep, D, C, exclude_edges=None, **kwargs):
    """admit_cheaper_routes on a dense hand-made problem graph (buffer nodes 0, 1; start 2; goal 3; d_max 5):
    edits the dense ``keep`` and returns which agents were admitted."""
    from agents.search.graph.edges import EdgeList, problem_edges
    from agents.search.graph.pruning import admissible, admit_cheaper_routes

    edges = problem_edges(EdgeList.short(D[:2, :2], C[:2, :2], 5.0), D, C, 2, 5.0)
    mask = keep[edges.u, edges.v]
    admitted = admit_cheaper_routes(mask, edges, D, C, 2, 5.0, admissible(edges, exclude_edges=exclude_edges),
                                    **kwargs)
    keep[:] = edges.dense(mask)
    return admitted


def test_admit_cheaper_routes_on_a_hand_made_graph():
    from agents.search.graph.edges import EdgeList
    from agents.search.graph.pruning import shortest_routes

    # buffer nodes 0, 1; start 2, goal 3. The cut-off keeps 2 -> 0 -> 1 -> 3 (cost 3 by 3 hops);
    # the plain shortest route 2 -> 3 costs 2 by one hop
    D = np.full((4, 4), 1.0)
    C = np.full((4, 4), 1.0)
    C[2, 3] = 2.0
    keep = np.zeros((4, 4), dtype=bool)
    keep[2, 0] = keep[0, 1] = keep[1, 3] = True
    kept = EdgeList.from_dense_mask(D, C, keep)
    assert shortest_routes(kept, None, np.array([2]), np.array([3])) == [[2, 0, 1, 3]]
    assert shortest_routes(kept, None, np.array([3]), np.array([2])) == [None]
    assert not admit(keep.copy(), D, C).any()  # 3 is within twice 2
    # but the detour is three times as long and costlier: it buys nothing
    assert admit(keep.copy(), D, C, detour=1.5).tolist() == [True]
    # as long, or no costlier: kept
    assert not admit(keep.copy(), D, C, detour=3.0).any()
    C[2, 3] = 3.0
    assert not admit(keep.copy(), D, C, detour=1.5).any()
    C[2, 3] = 2.0
    admitted = admit(keep, D, C, factor=1.0)
    assert admitted.tolist() == [True] and keep[2, 3]
    # the direct hop costing more than the detour is not admitted
    keep2 = np.zeros((4, 4), dtype=bool)
    keep2[2, 0] = keep2[0, 1] = keep2[1, 3] = True
    C[2, 3] = 5.0
    assert admit(keep2, D, C, factor=1.0).tolist() == [False] and not keep2[2, 3]
    # an excluded edge is never admitted: the plain route is then 2 -> 1 -> 3 (cost 2)
    C[2, 3] = 2.0
    keep3 = np.zeros((4, 4), dtype=bool)
    keep3[2, 0] = keep3[0, 1] = keep3[1, 3] = True
    admitted = admit(keep3, D, C, exclude_edges=np.array([[2, 3]]), factor=1.0)
    assert admitted.tolist() == [True]
    assert keep3[2, 1] and not keep3[2, 3]


def test_a_shortcut_no_chain_of_short_hops_corroborates_is_not_admitted():
    # start 2, goal 3; the cut-off keeps 2 -> 0 -> 1 -> 3 (hops of 2 steps, cost 3); the direct hop
    # costs 1. d_max 5: hops shorter than 2.5 corroborate, and the only chain is that route (6 steps);
    # the goal reads the start 8 steps away (more than 1.5 d_max)
    def graph(direct, reverse=8.0):
        D = np.full((4, 4), 4.9)
        D[2, 0] = D[0, 1] = D[1, 3] = 2.0
        D[2, 3] = direct
        D[3, 2] = reverse
        C = np.full((4, 4), 1.0)
        keep = np.zeros((4, 4), dtype=bool)
        keep[2, 0] = keep[0, 1] = keep[1, 3] = True
        return keep, D, C

    keep, D, C = graph(direct=2.6)  # 6 steps of chain for a hop of 2.6: a wormhole
    assert not admit(keep, D, C).any() and not keep[2, 3]
    keep, D, C = graph(direct=3.5)  # within twice the hop: a real shortcut
    assert admit(keep, D, C).tolist() == [True] and keep[2, 3]
    keep, D, C = graph(direct=2.6)
    assert admit(keep, D, C, corroboration=3.0).tolist() == [True]
    # a hop out of a sparse corner: no chain, but the critic reads it alike both ways
    keep, D, C = graph(direct=2.6, reverse=3.0)
    assert admit(keep, D, C).tolist() == [True] and keep[2, 3]


def test_a_second_critic_vouches_for_a_hop_nothing_else_backs():
    """A hop through a narrow passage with no node inside has no chain and reads long backwards, like a
    wormhole; a second critic that reads it short too gets it trusted, one that reads it long does not."""
    from scipy import sparse

    from agents.search.graph.pruning import trusted_edges

    # start 2, goal 3: the cut-off keeps 2 -> 0 -> 1 -> 3 (cost 3); the direct hop reads 2.6 steps (cost 1),
    # no chain backs it and the goal reads the start 8 steps away (more than 1.5 * d_max)
    D = np.full((4, 4), 4.9)
    D[2, 0] = D[0, 1] = D[1, 3] = 2.0
    D[2, 3], D[3, 2] = 2.6, 8.0
    C = np.full((4, 4), 1.0)
    keep = np.zeros((4, 4), dtype=bool)
    keep[2, 0] = keep[0, 1] = keep[1, 3] = True
    rows, cols = np.nonzero(D < 2.5)
    hops = sparse.csr_matrix((D[rows, cols], (rows, cols)), shape=D.shape)
    asked = []

    def second(reading):
        def confirm(u, v):
            asked.append((u.tolist(), v.tolist()))
            return np.full(len(u), reading)
        return confirm

    assert trusted_edges([2, 3], D, C, hops, d_max=5.0).tolist() == [False]
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0, confirm=second(3.0)).tolist() == [True]
    assert asked == [([2], [3])]
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0, confirm=second(19.5)).tolist() == [False]
    # only the hops nothing else backs are put to it (2 -> 0 -> 1 -> 3 has its chain)
    asked.clear()
    assert trusted_edges([2, 0, 1, 3], D, C, hops, d_max=5.0, confirm=second(19.5)).all() and asked == []
    assert not admit(keep.copy(), D, C, confirm=second(19.5)).any()
    k2 = keep.copy()
    assert admit(k2, D, C, confirm=second(3.0)).tolist() == [True] and k2[2, 3]
    # a hop that costs more than its steps can is not vouched for, whatever the second critic reads
    C[2, 3] = 7.5
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0, confirm=second(2.0)).tolist() == [False]


def test_the_planner_asks_its_second_opinion_on_observations():
    from agents.search.models import SecondOpinion

    band = band_pairwise(gap_y=11.5)

    def critic(a, b):  # reads every crossing of the band below its gap, right to left, 20 steps long
        D, C = band(a, b)
        a, b = np.asarray(a, float)[:, None, :], np.asarray(b, float)[None, :, :]
        D = np.where((a[..., 0] > 3.0) & (b[..., 0] < 3.0) & (np.maximum(a[..., 1], b[..., 1]) < 11.5), 20.0, D)
        return D, C

    class Second:
        def __init__(self, reading):
            self.reading, self.asked = reading, []

        def distance(self, a, b, aggregate="max"):
            self.asked.append((np.asarray(a).copy(), np.asarray(b).copy()))
            return np.full(len(a), self.reading)

    # no node at x = 3: no chain of short hops crosses the band, and the crossings read long backwards
    gx, gy = np.meshgrid([0.0, 1.0, 2.0, 4.0, 5.0, 6.0], np.arange(13.0))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    start, goal = np.array([[0.0, 0.0]]), np.array([[6.0, 0.0]])
    straight = {}
    for reading in (None, 2.0, 20.0):
        second = Second(reading)
        planner = make_planner(pts, critic, d_max=2.5, c_max=1.0,
                               second_opinion=None if reading is None else SecondOpinion(second))
        assert "second_opinion" not in planner.config()["graph"]
        assert planner.with_options(c_max=2.0).second_opinion is planner.second_opinion
        assert planner.sparsified(0.5)[0].second_opinion is planner.second_opinion
        plan = planner.plan(start, goal)
        assert plan.solved
        straight[reading] = bool(plan.waypoint_observations(0)[:, 1].max() < 2.0)
        if reading is not None:  # asked about the crossing, on observations
            a, b = second.asked[0]
            assert a.shape == b.shape == (1, 2) and a[0, 0] < 3.0 < b[0, 0]
    assert straight == {None: False, 2.0: True, 20.0: False}
    with pytest.raises(ValueError, match="distance critic"):
        SecondOpinion(object())


def test_a_hop_that_costs_more_than_its_steps_can_is_not_trusted():
    from scipy import sparse

    from agents.search.graph.pruning import trusted_edges

    # start 2, goal 3: the cut-off keeps 2 -> 0 -> 1 -> 3 (cost 15), the direct hop reads 2 steps
    D = np.full((4, 4), 2.0)
    C = np.full((4, 4), 5.0)
    keep = np.zeros((4, 4), dtype=bool)
    keep[2, 0] = keep[0, 1] = keep[1, 3] = True
    hops = sparse.csr_matrix(D)
    C[2, 3] = 6.0  # at most 1 a step: 2 steps may cost (with the margin) up to 2 * (2 + 1)
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0).tolist() == [True]
    assert admit(keep.copy(), D, C).tolist() == [True]
    C[2, 3] = 6.5  # a wormhole: two panoramas alike, far apart, and the cost critic sees the long way
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0).tolist() == [False]
    assert trusted_edges([2, 3], D, C, hops, d_max=5.0, cost_rate=3.0).tolist() == [True]
    assert trusted_edges([2, 0, 1, 3], D, C, hops, d_max=5.0).tolist() == [True, True, True]
    assert not admit(keep, D, C).any() and not keep[2, 3]


def test_the_endpoints_are_attached_once_for_the_graphs_of_one_place():
    """A stuck agent's replan tries several graphs from where it stands: the critic scores its start and
    goal against the nodes once, and again only for other endpoints."""
    pts = grid_points(5)
    inner = euclid_pairwise()
    calls = []

    def counting(a, b):
        calls.append((len(a), len(b)))
        return inner(a, b)

    planner = make_planner(pts, counting, d_max=1.6, proximity_radius=1.0)
    calls.clear()
    start, goal = np.array([[0.0, 2.0]]), np.array([[4.0, 2.0]])
    plain = planner.problem_graph(start, goal)
    n_calls = len(calls)
    assert n_calls > 0
    again = planner.problem_graph(start, goal, exclude=[7])
    assert len(calls) == n_calls  # not scored again
    fresh = make_planner(pts, inner, d_max=1.6, proximity_radius=1.0).problem_graph(start, goal, exclude=[7])
    assert (again.graph.distance != fresh.graph.distance).nnz == 0 and np.array_equal(again.D, plain.D)
    # so are the places to avoid (where parked agents stand), for the tries that keep clear of them
    parked = np.array([[2.0, 2.0]])
    clear = planner.problem_graph(start, goal, avoid=parked)
    n_calls = len(calls)
    again = planner.problem_graph(start, goal, exclude=[7], avoid=parked)
    assert len(calls) == n_calls
    fresh = make_planner(pts, inner, d_max=1.6, proximity_radius=1.0).problem_graph(start, goal, exclude=[7],
                                                                                      avoid=parked)
    assert (again.graph.distance != fresh.graph.distance).nnz == 0
    assert (clear.graph.distance != plain.graph.distance).nnz  # the edges past (2, 2) are gone
    planner.problem_graph(start, goal, avoid=parked + 1.0)
    assert len(calls) > n_calls  # other places: scored
    n_calls = len(calls)
    planner.problem_graph(start + 0.5, goal)
    assert len(calls) > n_calls  # another start: scored


def test_identical_goals_are_refused_naming_the_agents():
    planner = make_planner(grid_points(7), euclid_pairwise(), d_max=1.6)
    starts = np.array([[0.2, 0.2], [3.2, 3.2], [1.2, 4.2]])
    with pytest.raises(ValueError, match="agents 0 and 2 have the same goal"):
        planner.plan(starts, np.array([[5.1, 5.1], [2.1, 5.3], [5.1, 5.1]]))
    assert planner.plan(starts, np.array([[5.1, 5.1], [2.1, 5.3], [4.1, 0.1]])).solved
