"""CBS optimality against an independent joint-state brute force on tiny random instances."""
import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid

from agents.search.mapf import Proximity, solve_cbs, validate


def random_graph(rng, n, p_edge, directed=False, max_dur=1):
    """Random connected-ish graph as {(u, v): duration}."""
    edges = {}
    order = rng.permutation(n)
    for a, b in zip(order[:-1], order[1:]):  # a spanning path keeps most instances solvable
        d = int(rng.integers(1, max_dur + 1))
        edges[(int(a), int(b))] = d
        edges[(int(b), int(a))] = d
    for u in range(n):
        for v in range(n):
            if u != v and (u, v) not in edges and rng.random() < p_edge:
                d = int(rng.integers(1, max_dur + 1))
                edges[(u, v)] = d
                if not directed:
                    edges[(v, u)] = d
    return edges


def adjacency(n, edges):
    adj = [[] for _ in range(n)]
    for (u, v), d in sorted(edges.items()):
        adj[u].append((v, d))
    return adj


def pick(rng, n, k, crossing=False):
    """Random distinct starts and goals; with ``crossing`` each goal is the next agent's start
    (plus a random shift), which makes the agents' paths interact."""
    starts = [int(x) for x in rng.choice(n, size=k, replace=False)]
    if crossing:
        goals = starts[1:] + starts[:1]
    else:
        goals = [int(x) for x in rng.choice(n, size=k, replace=False)]
    return starts, goals


def check(n, edges, starts, goals, time_model, proximity=None, near=None, **kw):
    adj = adjacency(n, edges)
    unit = time_model == "unit"
    expected = brute_force_soc(n, edges, starts, goals, unit=unit, near=near)
    res = solve_cbs(adj, starts, goals, time_model=time_model, proximity=proximity, time_limit=20, **kw)
    if expected is None:
        assert res.status in ("infeasible", "timeout"), (res.status, res.soc)
        return None
    assert res.status == "optimal", (res.status, res.message, expected)
    assert res.soc == expected, (starts, goals, edges, res.paths)
    assert validate(adj, starts, goals, res.paths, time_model=time_model, proximity=proximity) == []
    return res


@pytest.mark.parametrize("seed", range(40))
def test_unit_time_random_graphs_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 8))
    edges = random_graph(rng, n, 0.15, directed=bool(seed % 4 == 3))
    k = 2 if seed % 3 else 3
    if k == 3 and n > 6:
        n, edges = 6, random_graph(rng, 6, 0.15)
    starts, goals = pick(rng, n, k, crossing=seed % 2 == 0)
    check(n, edges, starts, goals, "unit")
    check(n, edges, starts, goals, "unit", vanilla=True, node_limit=20000)


@pytest.mark.parametrize("seed", range(25))
def test_durative_random_graphs_match_brute_force(seed):
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(4, 7))
    edges = random_graph(rng, n, 0.15, max_dur=3)
    starts, goals = pick(rng, n, 2, crossing=seed % 2 == 0)
    check(n, edges, starts, goals, "durative")
    for spread in ("routes", "near"):  # spreading routes only breaks ties
        check(n, edges, starts, goals, "durative", spread=spread)


@pytest.mark.parametrize("seed", range(30))
def test_small_grids_with_symmetry_reasoning_match_brute_force(seed):
    """Grids exercise rectangle, corridor and target reasoning."""
    rng = np.random.default_rng(2000 + seed)
    h, w = (3, 4) if seed % 2 else (4, 4)
    n, edges, cells = random_grid(rng, h, w, 0.2)
    if n < 5:
        return
    k = 3 if (seed % 3 == 0 and n <= 9) else 2
    starts, goals = pick(rng, n, k, crossing=seed % 2 == 0)
    check(n, edges, starts, goals, "unit", grid_coords=cells)
    check(n, edges, starts, goals, "unit", grid_coords=cells, heuristic="cg", bypass=False)


@pytest.mark.parametrize("seed", range(30))
def test_open_grids_rectangle_reasoning_matches_brute_force(seed):
    """Open 5x5 grids: crossing agents create rectangle conflicts."""
    rng = np.random.default_rng(5000 + seed)
    n, edges, cells = random_grid(rng, 5, 5, 0.0 if seed % 3 else 0.12)
    # agent 0 enters at the top and leaves at the bottom, agent 1 enters at the left and leaves
    # at the right, with equal time offsets: all their cheapest paths cross in a rectangle
    c1 = int(rng.integers(1, 3))
    pts = [(0, c1), (c1, 0), (4, int(rng.integers(c1, 5))), (int(rng.integers(c1, 5)), 4)]
    if seed % 2:
        pts = [(4 - y, x) for y, x in pts]
    if (seed // 2) % 2:
        pts = [(y, 4 - x) for y, x in pts]
    index = {tuple(c): i for i, c in enumerate(cells.tolist())}
    if any(p not in index for p in pts) or len(set(pts)) < 4:
        return
    starts = [index[pts[0]], index[pts[1]]]
    goals = [index[pts[2]], index[pts[3]]]
    check(n, edges, starts, goals, "unit", grid_coords=cells)


@pytest.mark.parametrize("seed", range(15))
def test_proximity_matches_brute_force(seed):
    rng = np.random.default_rng(3000 + seed)
    n = 7
    edges = random_graph(rng, n, 0.2)
    pos = rng.uniform(0, 4, size=(n, 2))
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    radius = 1.0
    near = (dist < radius) | (dist.T < radius)
    np.fill_diagonal(near, False)
    starts, goals = pick(rng, n, 2, crossing=seed % 3 == 0)
    model = "unit" if seed % 2 else "durative"
    check(n, edges, starts, goals, model, proximity=Proximity(dist, radius), near=near)
    spread = ("routes", "near")[seed % 2]
    res = check(n, edges, starts, goals, model, proximity=Proximity(dist, radius), near=near, spread=spread)
    if res is not None and model == "durative":  # bounded: spreading may take longer routes, never too long
        adj = adjacency(n, edges)
        sub = solve_cbs(adj, starts, goals, time_model=model, proximity=Proximity(dist, radius), suboptimality=1.5,
                        spread=spread, time_limit=20)
        assert res.soc <= sub.soc <= 1.5 * res.soc
        assert validate(adj, starts, goals, sub.paths, time_model=model, proximity=Proximity(dist, radius)) == []


@pytest.mark.parametrize("seed", range(10))
def test_ecbs_cost_is_within_the_bound(seed):
    rng = np.random.default_rng(4000 + seed)
    n, edges, cells = random_grid(rng, 4, 4, 0.15)
    starts, goals = pick(rng, n, 3)
    adj = adjacency(n, edges)
    opt = solve_cbs(adj, starts, goals, grid_coords=cells, time_limit=20)
    if opt.status != "optimal":
        return
    for w in (1.2, 1.5, 2.0):
        sub = solve_cbs(adj, starts, goals, suboptimality=w, time_limit=20)
        assert sub.status in ("optimal", "suboptimal")
        assert opt.soc <= sub.soc <= w * opt.soc
        assert sub.lower_bound <= opt.soc
        assert validate(adj, starts, goals, sub.paths) == []
