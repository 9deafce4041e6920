"""Waypoint graph pruning and persistence, and single-agent search (incl. the risk-bounded mode)."""
import itertools

import numpy as np
import pytest

from agents.search.graph.build import WaypointGraph
from agents.search.graph.single import lagrangian_risk_path, risk_bounded_path, shortest_path


def stand_in(n=60, seed=0):
    """Points in a 20x20 square; distance = Euclidean, cost high near the centre."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 20, size=(n, 2))
    D = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    risk = np.exp(-np.linalg.norm(pts - 10.0, axis=1) ** 2 / 20.0)
    C = D * (risk[:, None] + risk[None]) / 2
    return pts, D, C


def test_pruning_keeps_exactly_the_short_and_safe_edges():
    pts, D, C = stand_in()
    g = WaypointGraph.from_matrices(D, C, d_max=5.0, c_max=0.5, observations=pts)
    src, dst, d, c = g.edge_arrays()
    expected = (D < 5.0) & (C < 0.5)
    np.fill_diagonal(expected, False)
    assert g.n_edges == expected.sum()
    assert np.array_equal(d, D[src, dst]) and np.allclose(c, C[src, dst])
    assert (d < 5.0).all() and (c < 0.5).all() and (src != dst).all()
    tighter = g.pruned(d_max=3.0)
    assert tighter.n_edges == ((D < 3.0) & (C < 0.5) & ~np.eye(len(D), dtype=bool)).sum()


def test_npz_round_trip(tmp_path):
    pts, D, C = stand_in()
    g = WaypointGraph.from_matrices(D, C, d_max=6.0, c_max=2.0, observations=pts.astype(np.float32), positions=pts)
    path = tmp_path / "graph.npz"
    g.save(path)
    h = WaypointGraph.load(path)
    assert (h.distance != g.distance).nnz == 0 and (h.cost != g.cost).nnz == 0
    assert np.array_equal(h.observations, g.observations) and np.array_equal(h.positions, pts)
    assert (h.d_max, h.c_max) == (6.0, 2.0)
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(ValueError, match="not a waypoint graph"):
        WaypointGraph.load(bad)
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="cannot read"):
        WaypointGraph.load(corrupt)


def test_bad_matrices_raise():
    with pytest.raises(ValueError, match="square"):
        WaypointGraph.from_matrices(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="NaN"):
        WaypointGraph.from_matrices(np.full((2, 2), np.nan))
    with pytest.raises(ValueError, match="negative"):
        WaypointGraph.from_matrices(-np.ones((2, 2)))
    with pytest.raises(ValueError, match="shape"):
        WaypointGraph.from_matrices(np.ones((2, 2)), np.ones((3, 3)))


def test_shortest_path_matches_dense_floyd_warshall():
    pts, D, C = stand_in(40, seed=3)
    g = WaypointGraph.from_matrices(D, C, d_max=6.0)
    W = np.where((D < 6.0) & ~np.eye(40, dtype=bool), D, np.inf)
    np.fill_diagonal(W, 0)
    for k in range(40):
        W = np.minimum(W, W[:, k:k + 1] + W[k:k + 1, :])
    for s, t in [(0, 1), (5, 17), (39, 2)]:
        plan = shortest_path(g, s, t)
        assert plan.nodes[0] == s and plan.nodes[-1] == t
        assert plan.distance == pytest.approx(W[s, t])


def test_weighted_objective_trades_distance_for_safety():
    pts, D, C = stand_in(80, seed=1)
    g = WaypointGraph.from_matrices(D, C, d_max=6.0)
    s = int(np.argmin(np.linalg.norm(pts - [2, 10], axis=1)))
    t = int(np.argmin(np.linalg.norm(pts - [18, 10], axis=1)))
    fast = shortest_path(g, s, t)
    safe = shortest_path(g, s, t, objective="weighted", beta=20.0)
    assert safe.cost < fast.cost and safe.distance >= fast.distance
    cheapest = shortest_path(g, s, t, objective="cost")
    assert cheapest.cost <= safe.cost + 1e-9


def test_unreachable_target_is_infeasible():
    D = np.array([[0, 1, 9], [1, 0, 9], [9, 9, 0]], float)
    g = WaypointGraph.from_matrices(D, d_max=5)
    assert shortest_path(g, 0, 2).status == "infeasible"
    assert risk_bounded_path(g, 0, 2, budget=10).status == "infeasible"
    with pytest.raises(ValueError, match="not in the graph"):
        shortest_path(g, 0, 7)


def brute_force_rcsp(D, C, keep, s, t, budget):
    n = len(D)
    best = (np.inf, None)
    others = [v for v in range(n) if v not in (s, t)]
    for r in range(len(others) + 1):
        for mid in itertools.permutations(others, r):
            path = (s, *mid, t)
            if not all(keep[a, b] for a, b in zip(path[:-1], path[1:])):
                continue
            d = sum(D[a, b] for a, b in zip(path[:-1], path[1:]))
            c = sum(C[a, b] for a, b in zip(path[:-1], path[1:]))
            if c <= budget + 1e-12 and d < best[0]:
                best = (d, path)
    return best


@pytest.mark.parametrize("seed", range(6))
def test_risk_bounded_path_is_optimal_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 7
    D = rng.uniform(1, 5, size=(n, n))
    C = rng.uniform(0, 3, size=(n, n))
    keep = rng.uniform(size=(n, n)) < 0.55
    np.fill_diagonal(keep, False)
    g = WaypointGraph.from_matrices(np.where(keep, D, 99), np.where(keep, C, 0), d_max=50)
    for budget in (1.0, 2.5, 5.0, np.inf):
        want_d, want_path = brute_force_rcsp(D, C, keep, 0, n - 1, budget)
        plan = risk_bounded_path(g, 0, n - 1, budget)
        if want_path is None:
            assert plan.status == "infeasible" and plan.nodes == []
        else:
            assert plan.status == "optimal"
            assert plan.distance == pytest.approx(want_d)
            assert plan.cost <= budget + 1e-9
        # the Lagrangian path meets the budget whenever any path does, never beats the optimum,
        # and its gap bound holds
        lag = lagrangian_risk_path(g, 0, n - 1, budget)
        if want_path is None:
            assert lag.status == "infeasible"
        else:
            assert lag.found and lag.cost <= budget + 1e-9
            assert lag.distance >= want_d - 1e-9
            assert lag.distance - want_d <= lag.stats.get("gap", 0.0) + 1e-9


def test_risk_budget_between_fast_and_safe_routes():
    pts, D, C = stand_in(80, seed=1)
    g = WaypointGraph.from_matrices(D, C, d_max=6.0)
    s = int(np.argmin(np.linalg.norm(pts - [2, 10], axis=1)))
    t = int(np.argmin(np.linalg.norm(pts - [18, 10], axis=1)))
    fast = shortest_path(g, s, t)
    cheapest = shortest_path(g, s, t, objective="cost")
    budget = (fast.cost + cheapest.cost) / 2
    plan = risk_bounded_path(g, s, t, budget)
    assert plan.status == "optimal" and plan.cost <= budget
    assert fast.distance <= plan.distance
    infeasible = risk_bounded_path(g, s, t, cheapest.cost * 0.5)
    assert infeasible.status == "infeasible" and "budget" in infeasible.stats["reason"]
    with pytest.raises(ValueError, match="budget"):
        risk_bounded_path(g, s, t, -1.0)


def test_endpoints_attach_with_pruning():
    pts, D, C = stand_in(30)
    g = WaypointGraph.from_matrices(D, C, d_max=6.0, observations=pts)
    starts = np.array([[1.0, 1.0], [19.0, 19.0]])
    goals = np.array([[19.0, 1.0], [1.0, 19.0]])
    dist = lambda a, b: np.linalg.norm(a[:, None] - b[None], axis=-1)  # noqa: E731
    zero = lambda a, b: np.zeros((len(a), len(b)))  # noqa: E731
    h, s_ids, g_ids = g.with_endpoints(
        dist(starts, pts), zero(starts, pts), dist(pts, goals), zero(pts, goals),
        dist(starts, goals), zero(starts, goals), observations=np.concatenate([starts, goals]))
    assert h.n_nodes == 34 and list(s_ids) == [30, 31] and list(g_ids) == [32, 33]
    row = h.distance[30].toarray().ravel()
    assert np.allclose(row[:30], np.where(dist(starts, pts)[0] < 6, dist(starts, pts)[0], 0))
    assert h.distance[:, 30].nnz == 0  # nothing leads back into a start
    plan = shortest_path(h, 30, 32)
    assert plan.found and all(n < 30 for n in plan.waypoints)
