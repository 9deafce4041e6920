"""max_leg: no leg that the second critic (the driver's) reads as too long to drive is planned."""
import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401  (registers the environments)
from agents.search import BufferPlanner, SearchPolicy, build_problem_graph
from agents.search.config import GraphConfig
from agents.search.graph.edges import EdgeList, problem_edges
from agents.search.graph.pruning import long_legs
from agents.search.models import SecondOpinion
from tests.conftest import StraightLineAgent

# a zigzag of nodes: hops of 2 along y = 0, hops of 1.41 up and down
ZIGZAG = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
START, GOAL = np.array([[-1.0, 0.0]]), np.array([[5.0, 0.0]])


def pairwise(a, b, cost=0.0):
    """Distance = length (>= 1); ``cost`` on every edge into or out of the middle node (2, 0)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = np.linalg.norm(b[None] - a[:, None], axis=-1)
    middle = (np.linalg.norm(a - [2.0, 0.0], axis=-1) < 1e-6)[:, None] | \
        (np.linalg.norm(b - [2.0, 0.0], axis=-1) < 1e-6)[None, :]
    return np.maximum(length, 1.0), cost * middle


class Reader:
    """A second critic that reads hops longer than 1.8 as 50 steps, and counts the pairs it reads."""

    def __init__(self):
        self.read = 0

    def __call__(self, a, b):
        self.read += len(a)
        length = np.linalg.norm(np.asarray(b) - np.asarray(a), axis=-1)
        return np.where(length > 1.8, 50.0, length)


def hops(plan):
    pts = plan.problem.observations
    route = list(plan.nodes[0]) + [int(plan.problem.goal_ids[0])]
    return np.linalg.norm(np.diff(pts[route], axis=0), axis=-1)


def test_long_legs_are_the_admissible_edges_read_beyond_the_limit():
    pts = np.concatenate([ZIGZAG, START, GOAL])
    D, C = pairwise(pts, pts)
    edges = problem_edges(EdgeList.short(D[:5, :5], C[:5, :5], 2.5), D, C, 5, 2.5)
    reader = Reader()
    found = long_legs(edges, pts, 5, reader, 10.0)
    allowed = edges.pairs()
    assert reader.read == len(allowed) and len(allowed) == int(((D < 2.5) & ~np.eye(7, dtype=bool)).sum()) - 4
    length = np.linalg.norm(pts[allowed[:, 1]] - pts[allowed[:, 0]], axis=-1)
    assert {tuple(e) for e in found} == {tuple(e) for e in allowed[length > 1.8]}
    assert (6, 4) not in {tuple(e) for e in found}  # a goal is only entered
    # with the buffer's own given, only the start's and goal's edges are read
    buffer_long = found[(found < 5).all(axis=1)]
    reader2 = Reader()
    again = long_legs(edges, pts, 5, reader2, 10.0, buffer_long=buffer_long)
    assert {tuple(e) for e in again} == {tuple(e) for e in found}
    assert reader2.read == len(allowed) - int(((allowed < 5).all(axis=1)).sum())


@pytest.mark.parametrize("cost, c_max", [(0.0, np.inf), (1.0, 0.01)])
def test_the_plan_takes_no_leg_the_second_critic_reads_long(cost, c_max):
    """Without cost, and where every route passes the middle node, whose edges are past the cut-off
    (so it is relaxed there)."""
    def pw(a, b):
        return pairwise(a, b, cost)

    D, C = pw(ZIGZAG, ZIGZAG)
    plain = BufferPlanner(ZIGZAG, D, C, pw, graph=GraphConfig(d_max=2.5, c_max=c_max),
                          second_opinion=Reader()).plan(START, GOAL)
    assert plain.solved and hops(plain).max() > 1.8  # the straight hops along y = 0
    planner = BufferPlanner(ZIGZAG, D, C, pw, graph=GraphConfig(d_max=2.5, c_max=c_max, max_leg=10.0),
                            second_opinion=Reader())
    plan = planner.plan(START, GOAL)
    assert plan.solved and hops(plan).max() <= 1.8
    if np.isfinite(c_max):
        assert plan.c_max > c_max  # the short hops pass the middle node: relaxed there
    assert planner.graph.max_leg == 10.0


def test_the_buffer_is_read_once_for_the_planners_with_options_makes():
    D, C = pairwise(ZIGZAG, ZIGZAG)
    reader = Reader()
    base = BufferPlanner(ZIGZAG, D, C, pairwise, graph=GraphConfig(d_max=2.5), second_opinion=reader)
    a = base.with_options(max_leg=10.0)
    a.plan(START, GOAL)
    first = reader.read
    b = base.with_options(max_leg=10.0, c_max=5.0)
    b.plan(START + 0.1, GOAL)
    buffer_pairs = len(EdgeList.short(D, C, 2.5))
    assert reader.read - first < first - buffer_pairs + 1  # only the new start's and goal's edges
    # graphs tried again for the same endpoints (a replan's) read nothing more
    reads = reader.read
    b.problem_graph(START + 0.1, GOAL)
    b.problem_graph(START + 0.1, GOAL, exclude=[2])
    assert reader.read == reads
    # another second opinion reads the buffer itself
    other = Reader()
    base.with_options(max_leg=10.0, second_opinion=other).plan(START, GOAL)
    assert other.read >= buffer_pairs


def test_max_leg_is_refused_without_a_reader_or_when_not_positive():
    D, C = pairwise(ZIGZAG, ZIGZAG)
    with pytest.raises(ValueError, match="max_leg"):
        BufferPlanner(ZIGZAG, D, C, pairwise, graph=GraphConfig(max_leg=10.0))
    with pytest.raises(ValueError, match="max_leg"):
        BufferPlanner(ZIGZAG, D, C, pairwise, graph=GraphConfig(max_leg=0.0), second_opinion=Reader())
    with pytest.raises(ValueError, match="second_opinion"):
        build_problem_graph(ZIGZAG, D, C, pairwise, START, GOAL, d_max=2.5, c_max=np.inf, max_leg=10.0)


@pytest.fixture(scope="module")
def two_agents():
    env = gym.make("SafeCentralObstacle-v0")
    u = env.unwrapped
    nodes = u.normalize(u.sample_states(60, np.random.default_rng(0))).astype(np.float32)
    critic, driver = StraightLineAgent(u.field, u.world_size), StraightLineAgent(u.field, u.world_size)
    env.close()
    return critic, driver, nodes


def test_a_saved_policy_keeps_max_leg_where_it_can_read_legs(two_agents, tmp_path):
    critic, driver, nodes = two_agents
    policy = SearchPolicy.from_models(critic, driver, nodes, d_max=12.0, max_leg=6.0)
    assert isinstance(policy.planner.second_opinion, SecondOpinion) and policy.planner.graph.max_leg == 6.0
    with pytest.raises(ValueError, match="max_leg"):  # the driver is the critic: no second opinion
        SearchPolicy.from_models(critic, critic, nodes, d_max=12.0, max_leg=6.0)
    path = policy.save(tmp_path / "graph")
    assert SearchPolicy.load(path, critic, driver).planner.graph.max_leg == 6.0
    assert SearchPolicy.load(path, critic).planner.graph.max_leg is None  # nothing to read legs with


def test_a_search_policy_with_a_fallback_plans_no_leg_it_would_hand_over(two_agents):
    critic, driver, nodes = two_agents
    beyond = {"fallback_beyond": 6.0}
    policy = SearchPolicy.from_models(critic, driver, nodes, d_max=12.0, fallback_model=critic, **beyond)
    assert policy.planner.second_opinion.model is driver and policy.planner.graph.max_leg == 6.0
    # no fallback, no hand-over, a second opinion that is not the driver's, or max_leg set: left as it is
    assert SearchPolicy.from_models(critic, driver, nodes, d_max=12.0, **beyond).planner.graph.max_leg is None
    assert SearchPolicy.from_models(critic, driver, nodes, d_max=12.0, fallback_model=critic,
                                    fallback_beyond=None).planner.graph.max_leg is None
    assert SearchPolicy.from_models(
        critic, driver, nodes, d_max=12.0, fallback_model=critic, **beyond, second_opinion=SecondOpinion(critic),
    ).planner.graph.max_leg is None
    kept = SearchPolicy.from_models(critic, driver, nodes, d_max=12.0, fallback_model=critic, **beyond,
                                    max_leg=float("inf"))
    assert kept.planner.graph.max_leg == float("inf")


def test_an_infinite_max_leg_reads_nothing():
    D, C = pairwise(ZIGZAG, ZIGZAG)
    reader = Reader()
    plan = BufferPlanner(ZIGZAG, D, C, pairwise, graph=GraphConfig(d_max=2.5, max_leg=np.inf),
                         second_opinion=reader).plan(START, GOAL)
    assert plan.solved and hops(plan).max() > 1.8 and reader.read == 0
    unread = BufferPlanner(ZIGZAG, D, C, pairwise, graph=GraphConfig(max_leg=np.inf))
    assert unread.graph.max_leg == np.inf  # needs no reader
