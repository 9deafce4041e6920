"""Attaching starts and goals scores only the pairs a plan can use, with the same answers.

``NodePairwise.within`` skips the pairs one member of the distance ensemble already puts at
``d_max`` or beyond (the planner's default aggregate is the ensemble's maximum, which that
member bounds from below). The problem graphs and plans must be those of scoring every pair.
"""
import gymnasium as gym
import numpy as np
import pytest
import torch as th

import safe_mapf_envs  # noqa: F401
from agents import load_pretrained
from agents.search.graph.build import NodePairwise
from agents.search.mapf import validate
from agents.search.planner import BufferPlanner
from agents.self_sampling import observations_at

ENV = "SafeCentralObstacle-v0"


@pytest.fixture(scope="module")
def setting():
    th.set_num_threads(1)
    env = gym.make(ENV)
    rng = np.random.default_rng(0)
    nodes = observations_at(env, env.unwrapped.sample_states(300, rng))
    ends = observations_at(env, env.unwrapped.sample_states(16, rng))
    model = load_pretrained(ENV, "unconstrained")
    planner = BufferPlanner.from_agent(model, nodes, solver="prioritized")
    assert isinstance(planner.pairwise, NodePairwise)
    every_pair = planner.pairwise.__call__  # a plain callable: no ``within``, every pair scored
    full = BufferPlanner(planner.observations, planner.D, planner.C, every_pair, planner.graph, planner.solver_config)
    return planner, full, ends[:8], ends[8:]


def test_problem_graph_is_that_of_scoring_every_pair(setting):
    planner, full, starts, goals = setting
    a, b = planner.problem_graph(starts, goals), full.problem_graph(starts, goals)
    ga, gb = a.graph.distance.tocsr(), b.graph.distance.tocsr()
    np.testing.assert_array_equal(ga.indptr, gb.indptr)
    np.testing.assert_array_equal(ga.indices, gb.indices)
    np.testing.assert_allclose(ga.data, gb.data, rtol=1e-5)
    np.testing.assert_allclose(a.graph.cost.tocsr().data, b.graph.cost.tocsr().data, rtol=1e-5, atol=1e-6)
    short = b.D < planner.graph.d_max
    np.testing.assert_array_equal(a.D < planner.graph.d_max, short)
    np.testing.assert_allclose(a.D[short], b.D[short], rtol=1e-5)
    assert np.all(a.D[~short] >= planner.graph.d_max)
    n = planner.observations.shape[0]
    scored = np.zeros_like(short)
    scored[:n, :n] = True  # buffer pairs come from the planner's matrices, all exact
    assert np.isinf(a.C[~short & ~scored]).mean() > 0.5  # most endpoint pairs were skipped


@pytest.mark.parametrize("solver", ["prioritized", "cbs"])
def test_plans_are_those_of_scoring_every_pair(setting, solver):
    planner, full, starts, goals = setting
    a = planner.with_options(solver=solver).plan(starts, goals)
    b = full.with_options(solver=solver).plan(starts, goals)
    assert a.solved and (a.status, a.soc, a.nodes, a.depart_times) == (b.status, b.soc, b.nodes, b.depart_times)
    dur = a.problem.graph.distance.copy()
    dur.data = np.maximum(np.ceil(dur.data - 1e-9), 1.0)
    prox = planner.problem_proximity(a.problem.D, len(starts))
    assert validate(dur, a.problem.start_ids, a.problem.goal_ids, a.cbs.paths, time_model="durative",
                    proximity=prox) == []


def test_attaching_new_endpoints_writes_over_the_last_matrices_only_where_nothing_uses_them():
    """A planner reuses the matrices of the last endpoints it attached for the next ones of as many
    agents (only their borders are written), unless a plan or problem graph made on them is alive."""
    from test_planner import euclid_pairwise, grid_points

    from agents.search import BufferPlanner

    pts = grid_points(12)
    pairwise = euclid_pairwise()
    D, C = pairwise(pts, pts)
    planner = BufferPlanner(pts, D, C, pairwise).with_options(d_max=2.5)
    first = planner.plan(pts[[0]] + 0.1, pts[[50]] + 0.1)
    kept = first.problem.D.copy()
    planner.plan(pts[[3]] + 0.1, pts[[70]] + 0.1)
    np.testing.assert_array_equal(first.problem.D, kept)  # alive: not written over
    del first
    before = id(planner._scratch[0])
    again = planner.plan(pts[[5]] + 0.1, pts[[90]] + 0.1)
    assert id(planner._scratch[0]) == before  # nothing used them: written over
    fresh = BufferPlanner(pts, D, C, pairwise).with_options(d_max=2.5).plan(pts[[5]] + 0.1, pts[[90]] + 0.1)
    np.testing.assert_array_equal(again.problem.D, fresh.problem.D)
    np.testing.assert_array_equal(again.problem.C, fresh.problem.C)
    assert again.nodes == fresh.nodes and again.soc == fresh.soc


def test_replans_score_the_buffer_against_each_parked_agent_once():
    """The buffer nodes' distances to each place to avoid are kept from one replan to the next, whichever
    places the next one avoids (only the new start's and goal's, and new places, are scored), and the graphs
    are those of a planner that scores everything anew."""
    from test_planner import euclid_pairwise, grid_points

    from agents.search import BufferPlanner

    pts = grid_points(12)
    pairwise = euclid_pairwise()
    scored = []

    def counting(a, b):
        scored.append(len(a) * len(b))
        return pairwise(a, b)

    D, C = pairwise(pts, pts)
    planner = BufferPlanner(pts, D, C, counting).with_options(d_max=2.5, proximity_radius=0.5)
    parked = pts[[30, 31, 77]] + 0.05
    for k, (s, g) in enumerate([(0, 50), (3, 70), (5, 90)]):
        scored.clear()
        plan = planner.plan(pts[[s]] + 0.1, pts[[g]] + 0.1, avoid=parked)
        # attaching: 2 endpoints against the buffer and each other; places: the buffer only the first time
        endpoints = 2 * (2 * len(pts)) + 4
        assert sum(scored) == endpoints + 2 * 2 * len(parked) + (2 * len(pts) * len(parked) if k == 0 else 0)
        fresh = BufferPlanner(pts, D, C, pairwise).with_options(d_max=2.5, proximity_radius=0.5)
        again = fresh.plan(pts[[s]] + 0.1, pts[[g]] + 0.1, avoid=parked)
        assert plan.solved and plan.nodes == again.nodes and plan.soc == again.soc
        assert (plan.problem.graph.distance != again.problem.graph.distance).nnz == 0
    # an agent has left: the buffer is not scored again; another has parked: against it alone
    for (s, g), avoid, new in (((7, 60), parked[:2], 0), ((9, 62), np.vstack([parked[:2], pts[[100]] + 0.05]), 1)):
        scored.clear()
        plan = planner.plan(pts[[s]] + 0.1, pts[[g]] + 0.1, avoid=avoid)
        assert sum(scored) == 2 * (2 * len(pts)) + 4 + 2 * 2 * len(avoid) + 2 * len(pts) * new
        again = BufferPlanner(pts, D, C, pairwise).with_options(d_max=2.5, proximity_radius=0.5).plan(
            pts[[s]] + 0.1, pts[[g]] + 0.1, avoid=avoid)
        assert plan.nodes == again.nodes and (plan.problem.graph.distance != again.problem.graph.distance).nnz == 0
