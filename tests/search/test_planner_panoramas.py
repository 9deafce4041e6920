"""The buffer planner on panorama nodes (the visual apartments), with a stand-in critic.

The planner never looks inside observations: it only hands them to the critic. The stand-in
critic here knows the position a panorama was rendered at (a lookup table, as a perfect
encoder would) and scores a pair by its straight-line length in steps (out of reach through
an obstacle) and the obstacle cost along it.
"""
import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401
from agents.search.config import GraphConfig, SolverConfig
from agents.search.mapf import Proximity, validate
from agents.search.planner import BufferPlanner
from agents.self_sampling import observations_at


class PanoramaOracle:
    def __init__(self, env):
        self.u = env.unwrapped
        self.env = env
        self.table = {}

    def observe(self, states):
        obs = observations_at(self.env, states)
        for o, s in zip(obs, states):
            self.table[o.tobytes()] = np.asarray(s, float)
        return obs

    def positions(self, obs):
        return np.stack([self.table[o.tobytes()] for o in obs])

    def pairwise(self, a, b):
        pa, pb = self.positions(a)[:, None, :], self.positions(b)[None, :, :]
        s = np.linspace(0.0, 1.0, 9)[:, None, None, None]
        pts = pa[None] + s * (pb - pa)[None]
        field = self.u.field
        length = np.linalg.norm(pb - pa, axis=-1) / self.u.action_scale  # in steps
        blocked = field.inside(pts).any(axis=0)
        cost = field.cost(pts).mean(axis=0) * length
        return np.where(blocked, 100.0, np.maximum(length, 1.0)), cost


@pytest.fixture(scope="module")
def world():
    env = gym.make("SafeApartment0-v0")
    oracle = PanoramaOracle(env)
    states = env.unwrapped.sample_states(300, np.random.default_rng(0))
    nodes = oracle.observe(states)
    D, C = oracle.pairwise(nodes, nodes)
    return env, oracle, states, nodes, D, C


def test_panorama_nodes_plan_valid_waypoints_for_several_agents(world):
    env, oracle, states, nodes, D, C = world
    assert nodes.shape[1:] == (4, 32, 32, 4) and nodes.dtype == np.uint8
    planner = BufferPlanner(
        nodes, D, C, oracle.pairwise, graph=GraphConfig(d_max=7.0, proximity_radius=1.5),
        solver=SolverConfig(suboptimality=1.0, time_limit=10.0),
    )
    rng = np.random.default_rng(1)
    starts_xy = env.unwrapped.sample_states(40, rng)
    # three agents with starts and goals far apart (several edges each)
    picks, goals_xy = [], []
    for s in starts_xy:
        g = starts_xy[np.argmax(np.linalg.norm(starts_xy - s, axis=1))]
        if all(np.linalg.norm(s - p) > 1.5 for p in picks) and all(np.linalg.norm(g - q) > 1.5 for q in goals_xy):
            picks.append(s)
            goals_xy.append(g)
        if len(picks) == 3:
            break
    starts, goals = oracle.observe(np.array(picks)), oracle.observe(np.array(goals_xy))
    plan = planner.plan(starts, goals)
    assert plan.solved, plan.message
    assert plan.status in ("optimal", "suboptimal")
    dur = plan.problem.graph.distance.copy()
    dur.data = np.maximum(np.ceil(dur.data - 1e-9), 1.0)
    n = len(nodes)
    prox = Proximity(plan.problem.D, planner.graph.proximity_radius)
    assert validate(dur, [n, n + 1, n + 2], [n + 3, n + 4, n + 5], plan.cbs.paths, time_model="durative",
                    proximity=prox) == []
    plans = plan.agent_plans()
    assert len(plans) == 3
    node_bytes = {n.tobytes() for n in nodes}
    for ap in plans.values():
        assert ap.goal.shape == (4, 32, 32, 4)
        # the controller's goal inputs are panoramas: buffer nodes (the start's own panorama first)
        assert ap.waypoints.shape[1:] == (4, 32, 32, 4)
        assert all(w.tobytes() in node_bytes for w in ap.waypoints[1:])
        # consecutive waypoints are within reach of the critic (no edge through a wall)
        pos = oracle.positions(np.concatenate([ap.waypoints, ap.goal[None]]))
        assert len(pos) >= 3
        d, _ = oracle.pairwise(np.concatenate([ap.waypoints, ap.goal[None]]),
                               np.concatenate([ap.waypoints, ap.goal[None]]))
        assert all(d[i, i + 1] < 7.0 + 1e-9 for i in range(len(pos) - 1))


def test_cost_pruned_panorama_plan_pays_less_predicted_cost(world):
    env, oracle, states, nodes, D, C = world
    base = BufferPlanner(
        nodes, D, C, oracle.pairwise, graph=GraphConfig(d_max=7.0),
        solver=SolverConfig(suboptimality=1.0, time_limit=10.0),
    )
    rng = np.random.default_rng(5)
    pts = env.unwrapped.sample_states(60, rng)
    far = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    i, j = np.unravel_index(np.argmax(far), far.shape)
    s, g = oracle.observe(pts[[i]]), oracle.observe(pts[[j]])
    plain = base.plan(s, g)
    cheap = base.with_options(c_max=float(np.quantile(C[D < 7.0], 0.5))).plan(s, g)
    assert plain.solved and cheap.solved
    assert sum(cheap.predicted_cost) <= sum(plain.predicted_cost) + 1e-9
