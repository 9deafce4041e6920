"""A cheap lower bound of the distance decides which pairs the critics read: the environment's
``min_steps`` and :class:`~agents.search.graph.build.NodePairwise`'s ``bound``."""
import pickle

import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401
from agents.algorithm import SafeGoalTD3
from agents.search.graph.build import NodePairwise

SMALL = dict(net_arch=[16, 16], features_extractor_kwargs={"net_arch": [16]})


def test_min_steps_bounds_what_an_agent_can_cover():
    env = gym.make("SafeCentralObstacle-v0").unwrapped  # 55 x 55 units, goal threshold 1, action scale 1
    a = env.normalize(np.array([[5.0, 5.0], [20.0, 5.0]]))
    b = env.normalize(np.array([[5.0, 5.5], [5.0, 35.0], [50.0, 50.0]]))
    steps = env.min_steps(a, b)
    gap = np.array([[0.0, 29.0, np.hypot(45, 45) - 1], [np.hypot(15, 0.5) - 1, np.hypot(15, 30) - 1,
                                                         np.hypot(30, 45) - 1]])
    np.testing.assert_allclose(steps, gap / np.sqrt(2), rtol=1e-5)
    # random actions never cover more than the bound says
    env.reset(seed=0)
    start = env.position.copy()
    for _ in range(10):
        env.step(env.action_space.sample())
    assert env.min_steps(env.normalize(start[None]), env.normalize(env.position[None]))[0, 0] <= 10
    with pytest.raises(ValueError, match="needs vector observations"):
        gym.make("SafeCentralObstacleVisual-v0").unwrapped.min_steps(a, b)
    # the same bound without the env, for other processes
    bound = pickle.loads(pickle.dumps(env.step_bound()))
    np.testing.assert_array_equal(bound(a, b), steps)


def test_a_bound_leaves_the_near_pairs_exact_and_reads_no_far_pair():
    model = SafeGoalTD3("MultiInputPolicy", "SafeCentralObstacle-v0", seed=0, device="cpu", policy_kwargs=SMALL)
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    rng = np.random.default_rng(0)
    nodes = env.observations_at(env.sample_states(60, rng))
    ends = env.observations_at(env.sample_states(8, rng))
    read = []

    def counting(a, b, rows, cols, **kw):
        read.append(len(rows))
        return model.pairwise_at(a, b, rows, cols, **kw)

    d_max = 12.0
    plain = NodePairwise(model, nodes)
    bounded = NodePairwise(model, nodes, bound=env.min_steps)
    bounded.model = type("Counting", (), {"pairwise": model.pairwise, "pairwise_at": staticmethod(counting),
                                          "encode_observations": model.encode_observations})()
    D0, C0 = plain.within(nodes, ends, d_max)
    D, C = bounded.within(nodes, ends, d_max)
    candidates = env.min_steps(nodes, ends) < d_max
    assert read == [candidates.sum()] and 0 < candidates.sum() < candidates.size
    keep = candidates & (D0 < d_max)
    np.testing.assert_allclose(D[keep], D0[keep], rtol=1e-5)
    np.testing.assert_allclose(C[keep], C0[keep], rtol=1e-5)
    # the pairs the bound rules out keep the bound (at least d_max) and no cost
    far = ~candidates
    np.testing.assert_allclose(D[far], env.min_steps(nodes, ends)[far], rtol=1e-5)
    assert (D[far] >= d_max).all() and np.isinf(C[far]).all()


def test_a_planner_built_with_a_bound_plans_as_one_built_without():
    from agents.search.planner import UNREAD_COST, BufferPlanner

    model = SafeGoalTD3("MultiInputPolicy", "SafeCentralObstacle-v0", seed=1, device="cpu", policy_kwargs=SMALL)
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    obs = env.observations_at(env.sample_states(80, np.random.default_rng(1)))
    # an untrained critic puts far pairs close; a large d_max keeps the comparison about the bound
    plain = BufferPlanner.from_agent(model, obs, d_max=40.0)
    fast = BufferPlanner.from_agent(model, obs, d_max=40.0, bound=env.min_steps)
    near = (env.min_steps(obs, obs) < 40.0) & (plain.D < 40.0)
    np.testing.assert_allclose(fast.D[near], plain.D[near], rtol=1e-5)
    assert (fast.D[~near] >= 40.0).all() and (fast.C[fast.D >= 40.0] == UNREAD_COST).all()
    np.fill_diagonal(near, False)
    assert fast.buffer_graph.n_edges == near.sum() > 0
