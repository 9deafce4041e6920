"""Fewer, better spread nodes: two-way consistency merging and the cap on edges per node."""
import numpy as np
import pytest

from agents.search import BufferPlanner
from agents.search.graph.edges import EdgeList
from agents.search.graph.sparsify import cap_out_edges, two_way_consistent


def line_world(points):
    p = np.asarray(points, np.float64)
    return np.abs(p[:, None] - p[None, :]) + 1.0  # a critic that reads 1 step from a node to itself


def test_nodes_the_critic_cannot_tell_apart_are_merged():
    D = line_world([0.0, 0.1, 5.0, 5.2, 10.0])
    assert two_way_consistent(D, tau=0.5).tolist() == [0, 2, 4]  # 1 is like 0, 3 like 2
    assert two_way_consistent(D, tau=0.0).tolist() == [0, 1, 2, 3, 4]  # all differ somewhere
    assert two_way_consistent(D, tau=0.5, order=[1, 0, 3, 2, 4]).tolist() == [1, 3, 4]
    # as goals seen from node 2, nodes 0 and 1 differ (a one-way passage); as starts they do not
    D2 = line_world([0.0, 0.1, 5.0])
    assert two_way_consistent(D2, tau=0.5, order=[0, 2, 1]).tolist() == [0, 2]
    D2[2, 1] = 50.0
    assert two_way_consistent(D2, tau=0.5, order=[0, 2, 1]).tolist() == [0, 1, 2]
    with pytest.raises(ValueError, match="tau"):
        two_way_consistent(D, tau=-1)
    with pytest.raises(ValueError, match="permutation"):
        two_way_consistent(D, tau=1, order=[0, 0, 1, 2, 3])


def test_merging_spreads_random_nodes_apart():
    rng = np.random.default_rng(0)
    pts = rng.random((300, 2)) * 20
    D = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + 1.0
    kept = two_way_consistent(D, tau=2.0)
    gaps = np.linalg.norm(pts[kept][:, None] - pts[kept][None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    assert 20 < len(kept) < 150 and gaps.min() > 1.0  # no two kept nodes within a step of each other


def test_cap_keeps_each_nodes_shortest_edges():
    D = line_world(np.arange(6.0))
    edges = EdgeList.short(D, D, 4.5)
    keep = np.ones(len(edges), bool)
    capped = edges.dense(cap_out_edges(keep.copy(), edges, k=2))
    assert (capped.sum(axis=1) <= 2).all() and (capped <= edges.dense()).all()
    assert capped[3].nonzero()[0].tolist() == [2, 4]  # its two nearest
    assert capped[0].nonzero()[0].tolist() == [1, 2]
    half = keep.copy()
    half[edges.find([3], [2])] = False  # a pruned edge is not counted: 3 keeps 4 and then 1 or 5
    assert edges.dense(cap_out_edges(half, edges, k=2))[3].nonzero()[0].tolist() == [1, 4]
    ones = EdgeList.short(np.ones((5, 5)), np.ones((5, 5)), 2.0)
    ends = ones.dense(cap_out_edges(np.ones(len(ones), bool), ones, k=1, n_buffer=3))
    assert ends[:3, :3].sum() == 3 and ends[3:, :].sum() == 8 and ends[:3, 3:].all()  # endpoints untouched
    with pytest.raises(ValueError, match="k must be"):
        cap_out_edges(keep, edges, k=0)


def test_planner_sparsified_and_capped(stand_in_models):
    import gymnasium as gym

    agent = stand_in_models["unconstrained"]
    env = gym.make("SafeCentralObstacle-v0")
    u = env.unwrapped
    obs = u.normalize(u.sample_states(200, np.random.default_rng(1))).astype(np.float32)
    env.close()
    planner = BufferPlanner.from_agent(agent, obs, d_max=10.0)
    small, kept = planner.sparsified(2.0)
    assert len(kept) < 200 and small.observations.shape == (len(kept), 2)
    np.testing.assert_array_equal(small.D, planner.D[np.ix_(kept, kept)])
    assert small.config() == planner.config()
    start, goal = obs[:1], obs[-1:]
    assert small.plan(start, goal).solved
    capped = planner.with_options(max_edges=4)
    g = capped.problem_graph(start, goal)
    assert (g.graph.distance[:200, :200].getnnz(axis=1) <= 4).all()
    assert capped.plan(start, goal).solved
    with pytest.raises(ValueError, match="max_edges"):
        planner.with_options(max_edges=0)
