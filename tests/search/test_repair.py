"""A graph that repairs itself: the edge memory, failed edges left out of later plans, localisation of a
lost agent, and save/load of the repaired graph (stand-in critic, no env, no torch)."""
import math

import numpy as np
import pytest

from agents.search import BufferPlanner, SearchPolicy
from agents.search.config import ControllerConfig, GraphConfig, ReplanConfig
from agents.search.execution import replanning
from agents.search.execution.repair import EdgeMemory, edges_near


class WallWorld:
    """Observations are points of a 10 x 10 room cut by a wall at x = 5 with one narrow door at (5, 5)
    that a straight line only passes if it starts or ends in it; the stand-in critic measures straight
    lines that do not cross the wall (100 steps if they do), its policy heads straight for the goal."""

    def _through_door(self, a, b, s):
        """Whether the lines ``a -> b``, crossing x = 5 at ``s`` of their length, pass a door."""
        return (np.linalg.norm(a - 5.0, axis=-1) < 0.3) | (np.linalg.norm(b - 5.0, axis=-1) < 0.3)

    def _seg(self, a, b):
        a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
        length = np.linalg.norm(b - a, axis=-1)
        dx = b[..., 0] - a[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (5.0 - a[..., 0]) / dx
            crosses = (dx != 0) & (s > 0) & (s < 1) & ~self._through_door(a, b, s)
        return np.where(crosses, 100.0, np.maximum(length, 1.0)), np.zeros_like(length)

    def pairwise(self, a, b, aggregate="max"):
        return self._seg(np.asarray(a)[:, None, :], np.asarray(b)[None, :, :])

    def distance(self, obs, goal, aggregate="max"):
        return self._seg(obs, goal)[0]

    def predict(self, batch, deterministic=True):
        d = np.asarray(batch["desired_goal"]) - np.asarray(batch["observation"])
        return (d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1.0)).astype(np.float32), None


def corridor_nodes():
    """Nodes on a 2-unit grid either side of the wall, and one node in the door."""
    xs = [1.0, 3.0, 4.5]
    left = [(x, y) for x in xs for y in (1.0, 3.0, 5.0, 7.0, 9.0)]
    right = [(10.0 - x, y) for x, y in left]
    return np.array(left + [(5.0, 5.0)] + right, dtype=np.float32)


@pytest.fixture
def world():
    return WallWorld()


@pytest.fixture
def planner(world):
    nodes = corridor_nodes()
    D, C = world.pairwise(nodes, nodes)
    return BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=None))


START = np.array([1.0, 1.0], np.float32)
GOAL = np.array([9.0, 9.0], np.float32)
DOOR = 15  # the node in the door


def drive_until_stuck(policy, target_edge):
    """Feed the policy the observations of its waypoints until it heads along ``target_edge``, then keep it
    standing at the edge's source (a stuck agent) until it replans; returns the route it was on."""
    obs = {"observation": START, "desired_goal": GOAL}
    policy.predict(obs)
    route = list(policy.routes["agent_0"])
    nodes = policy.planner.observations
    for _ in range(100):
        leg = policy.leg("agent_0")
        here = nodes[leg.source] if leg.source is not None else START
        if (leg.source, leg.target) == target_edge or policy.stats.replans:
            break
        policy.predict({"observation": nodes[leg.target], "desired_goal": GOAL})
    replans = policy.stats.replans
    for _ in range(200):
        if policy.stats.replans > replans:
            return route
        policy.predict({"observation": here, "desired_goal": GOAL})
    raise AssertionError("the agent never replanned")


def first_edge_into(route, node):
    i = route.index(node)
    return route[i - 1], route[i]


def edges_of(route):
    return set(zip(route[:-1], route[1:]))


def test_edge_memory_counts_removes_and_round_trips(tmp_path):
    m = EdgeMemory(10, limit=2)
    m.record_failure(1, 2)
    assert not m.is_removed(1, 2) and len(m) == 0  # one failure is below the limit
    m.record_failure(1, 2)
    assert m.is_removed(1, 2) and m.removed().tolist() == [[1, 2]]
    assert not m.is_removed(2, 1)  # directed
    m.record_success(1, 2)
    m.record_success(1, 2)
    assert not m.is_removed(1, 2)  # as many successes as failures: kept
    m.record_failure(3, 4)
    m.frozen = True
    m.record_failure(3, 4)
    m.record_success(5, 6)
    assert m.failures[(3, 4)] == 1 and (5, 6) not in m.successes  # frozen: nothing more is learned
    m.save(tmp_path / "m.npz")
    back = EdgeMemory.load(tmp_path / "m.npz")
    assert back.failures == m.failures and back.successes == m.successes and back.limit == 2
    with pytest.raises(ValueError, match="buffer nodes"):
        m.record_failure(3, 10)
    np.savez(tmp_path / "bad.npz", memory_meta=np.array([10, 1]), memory_failures=np.array([[1, 2, -1]]),
             memory_successes=np.zeros((0, 3)))
    with pytest.raises(ValueError, match="negative"):
        EdgeMemory.load(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match="not a saved edge memory"):
        EdgeMemory.from_arrays({})


def test_a_failed_edge_is_recorded_and_not_planned_again(world, planner):
    policy = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None))
    obs = {"observation": START, "desired_goal": GOAL}
    policy.predict(obs)
    first = list(policy.routes["agent_0"])
    assert DOOR in first  # the only way through the wall
    bad = first_edge_into(first, DOOR)
    drive_until_stuck(policy, bad)
    assert policy.memory.failures == {bad: 1} and policy.memory.is_removed(*bad)
    assert bad not in edges_of(policy.routes["agent_0"])  # the repaired plan leaves it out
    # the next episode plans without it from the start, and got-through edges count as successes
    assert policy.memory.successes and all(not policy.memory.is_removed(*e) for e in policy.memory.successes)
    policy.reset()
    policy.predict(obs)
    again = policy.routes["agent_0"]
    assert DOOR in again and bad not in edges_of(again)
    # a frozen memory still removes what it learned, and learns nothing more
    policy.memory.frozen = True
    policy.reset()
    route = drive_until_stuck(policy, first_edge_into(list(again), DOOR))
    assert route == list(again) and policy.memory.failures == {bad: 1}


def test_a_lost_agent_localises_and_replans_from_where_it_stands(world, planner):
    """Stuck in front of the door, banning the door's neighbourhood (and then the door) cuts every route:
    the agent plans again over the whole graph from where it stands instead of giving the door up."""
    policy = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None))
    policy.predict({"observation": START, "desired_goal": GOAL})
    route = list(policy.routes["agent_0"])
    before_door = first_edge_into(route, DOOR)
    drive_until_stuck(policy, before_door)
    new = policy.routes["agent_0"]
    assert policy.stats.replans == 1
    # a plan from its own position (the route's first node is the attached start) through the door
    assert new[0] >= len(planner.observations) and DOOR in new
    np.testing.assert_array_equal(policy.waypoints("agent_0")[0], planner.observations[before_door[0]])
    assert before_door not in edges_of(new)


def stand_until_replans(policy, obs, replans):
    """Keep the agent standing at ``obs`` until it has replanned ``replans`` times in all."""
    for _ in range(400):
        if policy.stats.replans >= replans:
            return
        policy.predict(obs)
    raise AssertionError("the agent never replanned")


class OpenWorld(WallWorld):
    """The room without its wall: the stand-in critic measures straight lines."""

    def _seg(self, a, b):
        length = np.linalg.norm(np.asarray(b, np.float64) - np.asarray(a, np.float64), axis=-1)
        return np.maximum(length, 1.0), np.zeros_like(length)


def test_an_agent_stuck_twice_on_its_only_way_heads_past_that_waypoint():
    """Nodes on a line, 2 apart, with edges only between neighbours: every route passes the node after the
    start. A learned policy can fail again and again on one waypoint (in a doorway, say) that it passes
    when it heads for the node beyond; stuck on it a second time, the agent heads past it, where the
    critic finds that hardly longer than going through it."""
    world = OpenWorld()
    nodes = np.array([(1.0 + 2 * i, 5.0) for i in range(5)], np.float32)
    D, C = world.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=None))
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=0.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=1.5),
    )
    here = {"observation": np.array([0.0, 5.0], np.float32), "desired_goal": np.array([9.5, 5.0], np.float32)}
    policy.predict(here)
    assert policy.routes["agent_0"][1] == 0  # the first node on the way
    stand_until_replans(policy, here, 1)
    assert policy.routes["agent_0"][1] == 0  # stuck once: the same way again (its only one)
    stand_until_replans(policy, here, 2)
    assert policy.routes["agent_0"][1] == 1  # stuck twice: it heads for the node beyond
    np.testing.assert_array_equal(policy.waypoints("agent_0")[1], nodes[1])


def test_past_failed_waypoints_skips_only_what_failed_twice_and_is_no_detour():
    from agents.search.execution.repair import past_failed_waypoints

    # nodes 0..4 on a line, 1 apart, and node 5 beside node 2 but behind a wall from node 0 (9 steps round it)
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 2.0])
    D = np.abs(x[:, None] - x[None, :])
    D[0, 5] = D[5, 0] = 9.0
    route, goal = [0, 1, 2, 3], 4
    assert past_failed_waypoints(route, goal, D, failed=[2]) == [0, 1, 2, 3]  # failed once: kept
    assert past_failed_waypoints(route, goal, D, failed=[2, 2]) == [0, 1, 3]
    assert past_failed_waypoints(route, goal, D, failed=[2, 3, 2, 3]) == [0, 1]  # then heads for the goal
    assert past_failed_waypoints(route, goal, D, failed=[0, 0]) == [0, 1, 2, 3]  # the start stays
    # the waypoint in the wall's door: heading past it is 9 steps against 1 + 1 through it
    assert past_failed_waypoints([0, 1], 5, D, failed=[1, 1]) == [0, 1]
    assert past_failed_waypoints([0, 1], 5, D, failed=[1, 1], detour=5.0) == [0]
    # a problem graph holds only a bound beyond d_max (here 2.5 for the 9 steps): heading past asks the critic
    bound = D.copy()
    bound[0, 5] = 2.5
    assert past_failed_waypoints([0, 1], 5, bound, failed=[1, 1]) == [0]  # misled by the bound
    assert past_failed_waypoints([0, 1], 5, bound, failed=[1, 1], straight=lambda u, w: D[u, w]) == [0, 1]


def test_an_agent_stuck_twice_in_front_of_a_door_keeps_the_door(world, planner):
    """Behind the door the critic sees a wall: heading past the door is no way, so the door stays."""
    policy = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None))
    policy.predict({"observation": START, "desired_goal": GOAL})
    before_door = first_edge_into(list(policy.routes["agent_0"]), DOOR)
    drive_until_stuck(policy, before_door)
    route = policy.routes["agent_0"]
    assert route[1] == DOOR
    stand_until_replans(policy, {"observation": planner.observations[before_door[0]], "desired_goal": GOAL}, 2)
    assert policy.routes["agent_0"][1] == DOOR


def test_save_and_load_keep_the_graph_and_what_it_learned(world, planner, tmp_path):
    policy = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None))
    policy.predict({"observation": START, "desired_goal": GOAL})
    drive_until_stuck(policy, first_edge_into(list(policy.routes["agent_0"]), DOOR))
    path = policy.save(tmp_path / "graph")
    assert path.name == "graph.npz" and path.exists()
    back = SearchPolicy.load(path, world, reach_threshold=1.5, safety_radius=None)
    assert back.memory.failures == policy.memory.failures and back.memory.successes == policy.memory.successes
    np.testing.assert_array_equal(back.planner.D, planner.D)
    assert back.planner.config() == planner.config()
    policy.reset()
    obs = {"observation": START, "desired_goal": GOAL}
    policy.predict(obs)
    back.predict(obs)
    assert back.routes["agent_0"] == policy.routes["agent_0"]  # the loaded graph plans around the failed edge
    assert SearchPolicy.load(path, world, c_max=3.0).planner.graph.c_max == 3.0
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a saved SearchPolicy graph"):
        SearchPolicy.load(tmp_path / "junk.npz", world)
    with pytest.raises(TypeError, match="unknown options"):
        SearchPolicy.load(path, world, colour="red")
    with pytest.raises(ValueError, match="edge memory is of a graph of 3 nodes"):
        SearchPolicy(planner, world, memory=EdgeMemory(3))


def test_replans_keep_clear_of_agents_parked_at_their_goals(world, planner):
    """Once agent_1 has arrived (it is no longer given to predict), a stuck agent_0 replans around the
    nodes by agent_1's goal, which now holds an immovable agent."""
    policy = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None))
    parked_goal = np.array([9.0, 5.0], np.float32)
    both = {"agent_0": {"observation": START, "desired_goal": GOAL},
            "agent_1": {"observation": np.array([9.0, 1.0], np.float32), "desired_goal": parked_goal}}
    policy.predict(both)
    assert policy.replanner.parked_nodes("agent_0") == []  # nobody has arrived yet
    policy.predict({"agent_0": both["agent_0"]})  # agent_1 arrived
    near = policy.replanner.parked_nodes("agent_0")
    d = np.linalg.norm(planner.observations[near] - parked_goal, axis=1)
    assert len(near) and (d < policy.config.replanning.ban_radius).all()
    nodes = planner.observations
    far = [i for i in range(len(nodes)) if i not in near]
    assert (np.linalg.norm(nodes[far] - parked_goal, axis=1) >= policy.config.replanning.ban_radius).all()
    for _ in range(200):  # agent_0 stands still where it is: it gets stuck and replans
        if policy.stats.replans:
            break
        policy.predict({"agent_0": both["agent_0"]})
    assert policy.stats.replans == 1 and not set(policy.routes["agent_0"]) & set(near)


def park_agent_1(planner, world, goal_0, goal_1, seen_at_goal=False):
    """A policy (ban radius 2.4) that has planned agent_0 from START to ``goal_0`` and agent_1 from (9, 1) to
    ``goal_1``, then seen agent_1 arrive (last seen at its start, or at its goal with ``seen_at_goal``);
    returns it and the agents' first observations."""
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=2.4),
    )
    both = {"agent_0": {"observation": START, "desired_goal": goal_0},
            "agent_1": {"observation": np.array([9.0, 1.0], np.float32), "desired_goal": goal_1}}
    policy.predict(both)
    if seen_at_goal:
        policy.predict({"agent_0": both["agent_0"], "agent_1": {"observation": goal_1, "desired_goal": goal_1}})
    policy.predict({"agent_0": both["agent_0"]})  # agent_1 arrived
    return policy, both


def test_by_an_agent_parked_beside_the_only_door_a_replan_keeps_the_widest_berth_left(world, planner):
    """agent_1 parks 1.8 from the only door, on the way to agent_0's goal: every route passes within the
    ban radius (2.4) of it, so a stuck agent_0 replans with the widest smaller berth that leaves one
    (0.7 of it): through the door, but clear of the nodes right by the parked agent, which the shortest
    route takes."""
    goal_0, goal_1 = np.array([9.0, 5.0], np.float32), np.array([6.8, 5.0], np.float32)
    policy, both = park_agent_1(planner, world, goal_0, goal_1)
    nodes = planner.observations
    assert DOOR in policy.replanner.parked_nodes("agent_0") and DOOR in policy.replanner.parked_nodes("agent_0", 0.85)
    berth = policy.replanner.parked_nodes("agent_0", 0.7)
    assert DOOR not in berth and len(berth)
    shortest = planner.plan(START[None], goal_0[None])
    assert set(shortest.nodes[0]) & set(berth)  # the shortest route passes right by the parked agent
    for _ in range(200):  # agent_0 stands still where it is: it gets stuck and replans
        if policy.stats.replans:
            break
        policy.predict({"agent_0": both["agent_0"]})
    route = policy.routes["agent_0"]
    assert policy.stats.replans == 1 and DOOR in route and not set(route) & set(berth)
    assert (np.linalg.norm(nodes[[i for i in route if i < len(nodes)]] - goal_1, axis=1) >= 0.7 * 2.4).all()


def test_where_every_berth_shuts_the_door_a_replan_still_keeps_off_the_parked_agent(world, planner):
    """agent_1 parks 1.25 past the only door, on the straight way to agent_0's goal: every berth (down to
    0.7 of the ban radius, 1.68) takes the door, so no route keeps one. The replan then goes through the
    door but round the parked agent, on no edge that passes it, rather than past it on the shortest way."""
    goal_0, goal_1 = np.array([9.0, 5.0], np.float32), np.array([6.25, 5.0], np.float32)
    planner = planner.with_options(proximity_radius=0.5)  # an edge passes a place it runs within 0.5 of
    policy, both = park_agent_1(planner, world, goal_0, goal_1, seen_at_goal=True)
    assert DOOR in policy.replanner.parked_nodes("agent_0", 0.7)
    nodes = planner.observations
    shortest = planner.plan(START[None], goal_0[None])
    ways = [nodes[i] for i in shortest.nodes[0] if i < len(nodes)] + [goal_0]

    def passes(a, b):  # the line a -> b runs through agent_1's disc (radius 0.5)
        t = np.clip(np.dot(goal_1 - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        return np.linalg.norm(a + t * (b - a) - goal_1) < 0.5

    assert any(passes(a, b) for a, b in zip(ways[:-1], ways[1:]))  # the shortest way runs through it
    for _ in range(200):  # agent_0 stands still where it is: it gets stuck and replans
        if policy.stats.replans:
            break
        policy.predict({"agent_0": both["agent_0"]})
    route = [i for i in policy.routes["agent_0"] if i < len(nodes)]
    ways = [nodes[i] for i in route] + [goal_0]
    assert policy.stats.replans == 1 and DOOR in route
    assert not any(passes(a, b) for a, b in zip(ways[:-1], ways[1:]))


def test_an_agent_does_not_park_where_it_would_shut_another_out(world, planner):
    """agent_1's goal lies 1.5 from the only door; agent_0's every way to its goal goes through the door.
    With ``park_clearance`` agent_1 parks only after agent_0 has arrived; without it (the default), nothing
    holds it (agent_0's route passes the goal at no point the planner calls near)."""
    goal_1 = np.array([6.5, 5.0], np.float32)
    both = {"agent_0": {"observation": START, "desired_goal": GOAL},
            "agent_1": {"observation": np.array([9.0, 1.0], np.float32), "desired_goal": goal_1}}
    plain = SearchPolicy(planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None,
                                                                     hold="order"))
    plain.predict(both)
    assert plain._goal_blockers("agent_1") == []
    policy = SearchPolicy(
        planner, world,
        controller=ControllerConfig(reach_threshold=1.5, safety_radius=None, hold="order", park_clearance=2.0),
    )
    policy.predict(both)
    assert DOOR in policy.routes["agent_0"]
    assert policy._goal_blockers("agent_1") == [("agent_0", len(policy.routes["agent_0"]))]
    assert policy._goal_blockers("agent_0") == []  # agent_1 has a way around agent_0's goal
    with pytest.raises(ValueError, match="park_clearance"):
        SearchPolicy(planner, world, controller=ControllerConfig(park_clearance=0.0))


def test_cut_off_tells_a_cut_way_from_no_way():
    from scipy import sparse

    from agents.search.execution.dependencies import cut_off

    # a path 0 - 1 - 2 - 3 and a detour 0 - 4 - 3 around node 1 and 2
    edges = [(0, 1), (1, 2), (2, 3), (0, 4), (4, 3)]
    rows, cols = zip(*edges)
    adj = sparse.csr_matrix((np.ones(len(edges)), (rows, cols)), shape=(6, 6))
    ban = np.array([False, True, True, False, False, False])
    assert not cut_off(adj, 0, 3, ban)  # the detour
    ban[4] = True
    assert cut_off(adj, 0, 3, ban)  # every way passes the banned nodes
    assert not cut_off(adj, 0, 5, ban)  # no way at all: not cut off by the ban
    assert not cut_off(adj, 0, 3, np.array([True, False, False, True]))  # source and target stay in


def test_a_replan_does_not_pass_where_a_parked_agent_stands():
    """agent_1 arrives short of its goal (an agent parks where it first comes within the goal radius),
    standing on the straight way of agent_0, which gets stuck against it. Its replans leave out the nodes
    by agent_1's goal (none here) and every edge that passes where agent_1 was last seen, so agent_0
    goes around it; without that the replan runs straight through it again."""
    world = OpenWorld()
    nodes = np.array([(x, y) for x in (1.0, 3.0, 5.0, 7.0, 9.0) for y in (1.0, 3.0, 5.0, 7.0, 9.0)], np.float32)
    D, C = world.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=1.0))
    start, goal_0 = np.array([3.0, 5.0], np.float32), np.array([7.0, 5.0], np.float32)
    stands = np.array([5.0, 5.0], np.float32)  # where agent_1 parks, short of its goal
    both = {"agent_0": {"observation": start, "desired_goal": goal_0},
            "agent_1": {"observation": np.array([5.0, 3.0], np.float32),
                        "desired_goal": np.array([5.0, 5.6], np.float32)}}
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=0.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=0.5),
    )
    policy.predict(both)
    policy.predict({**both, "agent_1": {**both["agent_1"], "observation": stands}})
    assert 12 in policy.routes["agent_0"]  # straight on, by the node at (5, 5)
    stand_until_replans(policy, {"agent_0": both["agent_0"]}, 1)  # agent_1 arrived; agent_0 is stuck
    route = [int(i) for i in policy.routes["agent_0"] if i < len(nodes)]
    assert policy.replanner.parked_nodes("agent_0") == [] and 12 not in route and len(route) >= 3
    ways = np.concatenate([[start], nodes[route], [goal_0]]).astype(np.float64)
    along = np.linspace(0.0, 1.0, 21)[:, None]
    clear = [np.linalg.norm(a + along * (b - a) - stands, axis=1).min() for a, b in zip(ways[:-1], ways[1:])]
    assert min(clear) >= 1.9  # every leg goes around it


def test_passing_edges_are_those_that_go_through_a_place():
    from agents.search.graph.build import passing_edges

    world = OpenWorld()
    pts = np.array([(0.0, 0.0), (4.0, 0.0), (2.0, 3.0), (2.0, 0.5)], np.float32)
    D, _ = world.pairwise(pts, pts)
    pairs = passing_edges(D, pts, world.pairwise, np.array([(2.0, 0.0)], np.float32), slack=1.0)
    out = np.zeros(D.shape, bool)
    out[pairs[:, 0], pairs[:, 1]] = True
    assert out[0, 1] and out[1, 0]  # straight through it
    assert out[0, 3] and out[3, 1]  # ending by it (within the slack), starting by it
    assert not out[0, 2] and not out[2, 1] and not out[2, 0]  # well clear of it
    assert not out.diagonal().any()


def test_edges_near_a_failed_edge_are_those_between_the_two_places():
    from agents.search.execution.repair import edges_near

    pts = np.array([(0.0, 0.0), (0.5, 0.0), (9.0, 0.0), (9.4, 0.0), (5.0, 0.0)])
    D = np.abs(pts[:, None, 0] - pts[None, :, 0])
    pairs = {tuple(e) for e in edges_near(D, 0, 2, radius=1.0).tolist()}
    assert pairs == {(0, 2), (0, 3), (1, 2), (1, 3)}  # from the first place to the second, not back
    assert {tuple(e) for e in edges_near(D, 0, 1, radius=1.0).tolist()} == {(0, 1), (1, 0)}


def test_a_stuck_agent_leaves_out_the_edges_beside_the_one_it_failed_on(world, planner):
    """Two panoramas alike make the critic take two far places for near ones, between every pair of
    nodes right by them: after failing on one such edge, an agent's replans leave them all out."""
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=2.5),
    )
    policy.predict({"observation": START, "desired_goal": GOAL})
    bad = first_edge_into(list(policy.routes["agent_0"]), DOOR)
    drive_until_stuck(policy, bad)
    out = {tuple(e) for e in policy.replanner.exclude_edges("agent_0").tolist()}
    D = planner.D
    beside = [(u, v) for u in range(len(D)) for v in range(len(D)) if u != v
              and min(D[u, bad[0]], D[bad[0], u]) < 2.5 and min(D[v, bad[1]], D[bad[1], v]) < 2.5]
    assert bad in out and len(beside) > 1 and set(beside) <= out
    assert policy.memory.failures == {bad: 1}  # the memory counts the edge it failed on only


class TwinWorld(OpenWorld):
    """The open room, but its corner by (1, 1) looks like the place by (9, 5): from every point within 1.5 of
    (1, 1) the stand-in critic takes every node within 2.5 of (9, 5) for one a single step away, except the
    node at (9, 7) from points right of x = 1.2 (where it sees that node is far)."""

    def _seg(self, a, b):
        d, c = super()._seg(a, b)
        a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
        twin = (np.linalg.norm(a - 1.0, axis=-1) < 1.5) & (np.linalg.norm(b - [9.0, 5.0], axis=-1) < 2.5)
        seen = (a[..., 0] > 1.2) & (np.linalg.norm(b - [9.0, 7.0], axis=-1) < 0.1)
        return np.where(twin & ~seen, 1.0, d), c


def test_an_agent_that_lost_the_node_it_set_off_for_links_no_more_to_nodes_beside_it():
    """A start attached to a far place the critic takes for a near one (a wormhole from where the agent
    stands): stuck a little further on, where the critic finds that node far, the agent's replans no longer
    link its start to the nodes beside it (the critic still takes them for near ones); without
    ``detach_radius`` they do, and where the critic still finds the node near (a hard edge, not a wormhole)
    nothing is detached."""
    world = TwinWorld()
    nodes = np.array([(x, y) for x in (1.0, 3.0, 5.0, 7.0, 9.0) for y in (1.0, 3.0, 5.0, 7.0, 9.0)], np.float32)
    D, C = world.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=None))
    twins = set(np.flatnonzero(np.linalg.norm(nodes - [9.0, 5.0], axis=1) < 2.5).tolist())
    goal = np.array([9.0, 9.0], np.float32)
    start, further = np.array([1.0, 1.0], np.float32), np.array([1.3, 1.0], np.float32)
    firsts, detached = {}, {}
    for radius, where in ((None, "further"), (3.0, "further"), (3.0, "start")):
        stuck_at = further if where == "further" else start
        policy = SearchPolicy(
            planner, world, controller=ControllerConfig(reach_threshold=0.5, safety_radius=None),
            replanning=ReplanConfig(ban_radius=0.5, detach_radius=radius),
        )
        policy.predict({"observation": start, "desired_goal": goal})
        bad = policy.routes["agent_0"][1]
        assert np.allclose(nodes[bad], (9.0, 7.0))  # the wormhole: a single step to the far place
        stand_until_replans(policy, {"observation": stuck_at, "desired_goal": goal}, 1)
        firsts[radius, where] = policy.routes["agent_0"][1]
        detached[radius, where] = set(policy.episode.states["agent_0"].detached)
    beside = {i for i in range(len(nodes)) if min(D[i, bad], D[bad, i]) < 3.0} | {bad}
    assert firsts[None, "further"] in twins - {bad}  # the next node beside it
    assert detached[3.0, "further"] == beside and firsts[3.0, "further"] not in beside  # a way through the room
    assert detached[3.0, "start"] == set()  # it still finds the node near: nothing detached
    with pytest.raises(ValueError, match="detach_radius"):
        SearchPolicy(planner, world, replanning=ReplanConfig(detach_radius=-1.0))


class GoalTwinWorld(OpenWorld):
    """The open room, but the stand-in critic takes every point within 2.5 of (1, 9) for one a single step
    from the goal at (9, 9)."""

    def _seg(self, a, b):
        d, c = super()._seg(a, b)
        a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
        twin = (np.linalg.norm(a - [1.0, 9.0], axis=-1) < 2.5) & (np.linalg.norm(b - 9.0, axis=-1) < 0.1)
        return np.where(twin, 1.0, d), c


def test_an_agent_that_lost_its_goal_on_the_last_leg_links_no_more_nodes_beside_that_legs_start_to_it():
    """The critic takes a corner for a place beside the goal: every node there is one step from the goal.
    Stuck on the last leg where the critic finds the goal far, the agent's replans no longer link the
    nodes beside the one it set off from to its goal; without ``detach_radius`` they link the next one."""
    world = GoalTwinWorld()
    nodes = np.array([(x, y) for x in (1.0, 3.0, 5.0, 7.0) for y in (1.0, 3.0, 5.0, 7.0, 9.0)], np.float32)
    D, C = world.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=None))
    corner = set(np.flatnonzero(np.linalg.norm(nodes - [1.0, 9.0], axis=1) < 2.5).tolist())
    goal = np.array([9.0, 9.0], np.float32)
    lasts, detached = {}, {}
    for radius in (None, 3.0):
        policy = SearchPolicy(
            planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None),
            replanning=ReplanConfig(ban_radius=0.5, detach_radius=radius),
        )
        obs = {"observation": np.array([1.0, 1.0], np.float32), "desired_goal": goal}
        policy.predict(obs)
        assert policy.routes["agent_0"][-1] in corner  # the wormhole: one step from the corner to the goal
        while policy.leg("agent_0").target is not None:  # drive along the route to its last node
            obs = {"observation": nodes[policy.leg("agent_0").target], "desired_goal": goal}
            policy.predict(obs)
        source = policy.leg("agent_0").source
        stand_until_replans(policy, {"observation": np.array([3.0, 5.0], np.float32), "desired_goal": goal}, 1)
        lasts[radius] = policy.routes["agent_0"][-1]
        detached[radius] = set(policy.episode.states["agent_0"].goal_detached)
    assert lasts[None] in corner - {source}  # the next corner node
    beside = {i for i in range(len(nodes)) if min(D[i, source], D[source, i]) < 3.0} | {source}
    assert detached[None] == set() and detached[3.0] == beside and corner <= beside
    assert lasts[3.0] not in corner  # a way through the room


class TwoDoorWorld(WallWorld):
    """A wall at x = 5 with a wide door (y 4-6) and a narrow one far up (y 9-10); the stand-in critic
    measures straight lines that cross the wall only through a door (100 steps where they do not)."""

    def _through_door(self, a, b, s):
        y = a[..., 1] + s * (b[..., 1] - a[..., 1])  # where the line crosses x = 5
        return ((y >= 4.0) & (y <= 6.0)) | ((y >= 9.0) & (y <= 10.0))


def two_door_world():
    """The two-door world, its planner (nodes either side and three in the doors: the wide door's lower
    and upper node and the far door's), and the ids of the three door nodes."""
    world = TwoDoorWorld()
    side = [(x, y) for x in (1.5, 3.5) for y in (1.0, 2.5, 4.0, 5.5, 7.0, 8.5, 10.0)]
    doors = [(5.0, 4.3), (5.0, 5.7), (5.0, 9.5)]
    nodes = np.array(side + doors + [(10.0 - x, y) for x, y in side], np.float32)
    D, C = world.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, world.pairwise, graph=GraphConfig(d_max=2.5, proximity_radius=None))
    return world, planner, (len(side), len(side) + 1, len(side) + 2)


@pytest.mark.parametrize("ban_detour", [math.inf, 0.0])
def test_a_replan_keeps_clear_of_the_failed_waypoint_alone_where_its_neighbourhood_holds_the_short_way(ban_detour):
    """Stuck on the way to one of two nodes in a wide door: banning the failed node's neighbourhood bans the
    door's other node too and sends the agent round by the far door; with ``ban_detour`` the replan keeps
    clear of the failed node alone where that is more than ``ban_detour`` predicted steps shorter."""
    world, planner, (low, high, far) = two_door_world()
    nodes = planner.observations
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=2.0, ban_detour=ban_detour),
    )
    start, goal = np.array([1.5, 4.0], np.float32), np.array([8.5, 4.0], np.float32)
    policy.predict({"observation": start, "desired_goal": goal})
    route = list(policy.routes["agent_0"])
    assert low in route and far not in route  # through the wide door, by its lower node
    # drive along the route until the leg into the door, then stand at that leg's start until it replans
    while policy.leg("agent_0").target != low:
        policy.predict({"observation": nodes[policy.leg("agent_0").target], "desired_goal": goal})
    stand_until_replans(policy, {"observation": nodes[policy.leg("agent_0").source], "desired_goal": goal}, 1)
    new = policy.routes["agent_0"]
    assert low not in new
    if ban_detour == math.inf:  # the whole wide door is banned: round by the far one
        assert far in new and high not in new and policy.narrow_replans == 0
    else:
        assert high in new and far not in new and policy.narrow_replans == 1
    assert SearchPolicy(planner, world).config.replanning.ban_detour == math.inf  # never, by default
    with pytest.raises(ValueError, match="ban_detour"):
        SearchPolicy(planner, world, replanning=ReplanConfig(ban_detour=-1.0))


def circling(centre, t):
    """A point 0.3 from ``centre`` that goes round it every 5 steps (an agent that moves: not stuck)."""
    a = 2 * math.pi * t / 5
    return (np.asarray(centre) + 0.3 * np.array([math.cos(a), math.sin(a)])).astype(np.float32)


@pytest.mark.parametrize("repair, stretch", [(True, 2.0), (False, 2.0), (True, 1.0)])
def test_an_agent_about_to_take_an_edge_another_agent_failed_on_plans_around_it_first(repair, stretch, monkeypatch):
    """Two agents from the same start through the wide door: the first is stuck on the leg into the door's
    lower node and replans; the second, about to set off into the door later along one of the edges
    recorded with that failure, plans around them first (``repair_routes``), instead of failing on them
    in turn; but not where that route is more than ``REPAIR_STRETCH`` times as long as the rest of its own
    (the way round is a little longer here)."""
    monkeypatch.setattr(replanning, "REPAIR_STRETCH", stretch)
    world, planner, (low, _, _) = two_door_world()
    nodes = planner.observations
    policy = SearchPolicy(
        planner, world, controller=ControllerConfig(reach_threshold=1.5, safety_radius=None),
        replanning=ReplanConfig(ban_radius=2.0, repair_routes=repair),
    )
    start, goal = np.array([1.5, 4.0], np.float32), np.array([8.5, 4.0], np.float32)
    goal_1 = goal + np.array([0.0, 0.5], np.float32)  # goals of their own, side by side
    t = 0

    def step(first, second):
        nonlocal t
        t += 1
        policy.predict({"agent_0": {"observation": first, "desired_goal": goal},
                        "agent_1": {"observation": second, "desired_goal": goal_1}})

    step(start, start)
    route = list(policy.routes["agent_0"])
    assert low in route
    # the first agent drives to the leg into the door and stands at its start until it replans; the
    # second one circles by its start meanwhile
    while policy.leg("agent_0").target != low:
        step(nodes[policy.leg("agent_0").target], circling(start, t))
    source = policy.leg("agent_0").source
    failed = {(int(u), int(v)) for u, v in edges_near(planner.D, source, low, 2.0)}
    assert edges_of(policy.routes["agent_1"]) & failed  # the second agent's route takes one of them
    while policy.stats.replans == 0:
        step(nodes[source], circling(start, t))
    leg = policy.leg("agent_1")
    assert (leg.source, leg.target) not in failed  # the second agent has not come to those edges yet
    # now the second agent drives its route, standing one step at the start of each leg
    taken, here, at = [], start, None  # the legs it set off along, from the node it stood at
    for _ in range(40):
        step(circling(nodes[source], t), here)
        leg = policy.leg("agent_1")
        at = leg.source if leg.source is not None else at
        taken.append((at, leg.target))
        if leg.target is None:
            break
        here, at = nodes[leg.target], leg.target
        step(circling(nodes[source], t), here)
    assert taken[-1][1] is None  # on its way to the goal
    if repair and stretch > 1.0:
        assert policy.route_repairs == 1 and not failed & set(taken)
    else:
        assert policy.route_repairs == 0 and failed & set(taken)
    assert policy.stats.replans == 1  # only the first agent got stuck
    assert not SearchPolicy(planner, world).config.replanning.repair_routes  # off by default
