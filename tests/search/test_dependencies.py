"""Execution that survives delays: plan-order dependencies, the controller keeping them, and a slowed agent."""
import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs
from agents.search import SearchPolicy
from agents.search.config import ControllerConfig
from agents.search.execution.controller import AgentPlan, WaypointController
from agents.search.execution.dependencies import plan_dependencies, proximity_relation
from agents.search.execution.episode import AgentState, Episode
from agents.search.execution.ordering import hold_cycle


def test_the_agent_the_plan_sends_second_waits_for_the_first():
    # nodes 0..4 on a line; agent 0 passes node 2 at time 2 and reaches node 3 at time 3; agent 1 crosses
    # node 2 at time 5 (coming from node 9, going to its goal 8)
    close = np.eye(10, dtype=bool)
    deps = plan_dependencies(routes=[[0, 1, 2, 3], [9, 2]], arrivals=[[0, 1, 2, 3], [0, 5]],
                             departures=[[0, 1, 2, 3], [0, 5]], goals=[4, 8], goal_arrivals=[4, 6], close=close)
    assert deps[1] == {1: [(0, 3)]}  # agent 1 sets off for node 2 once agent 0 has reached node 3 (left node 2)
    assert deps[0] == {}
    # if agent 0 reaches node 3 only after agent 1's arrival at node 2, agent 1 waits for it to get to node 2 only
    deps = plan_dependencies([[0, 1, 2, 3], [9, 2]], [[0, 1, 2, 7], [0, 5]], [[0, 1, 2, 7], [0, 5]], [4, 8], [8, 6],
                             close)
    assert deps[1] == {1: [(0, 2)]}
    # an agent's goal is its last target: one that would park by another's route waits until it has passed
    close[4, 2] = close[2, 4] = True
    deps = plan_dependencies([[0, 1, 2, 3], [9, 5]], [[0, 1, 2, 3], [0, 1]], [[0, 1, 2, 3], [0, 1]], [4, 2], [4, 9],
                             close)
    assert deps[1][2] == [(0, 4)]  # agent 1 parks on node 2 (near agent 0's goal) after agent 0 arrived
    with pytest.raises(ValueError, match="one entry per agent"):
        plan_dependencies([[0]], [[0], [1]], [[0], [1]], [1], [1], close)
    with pytest.raises(ValueError, match="departure times"):
        plan_dependencies([[0, 1]], [[0, 1]], [[0]], [2], [3], close)


def wait_cycle(deps, lengths):
    """Whether the controller's waits have a cycle: ``(a, q)`` = a sets off for its target q, after
    ``(a, q - 1)`` and, for a dependency ``(i, r)`` of target q, after ``(i, r + 1)`` (Kahn's algorithm)."""
    after = {(a, q): [(a, q - 1)] if q > 1 else [] for a, n in enumerate(lengths) for q in range(1, n + 2)}
    for j, d in enumerate(deps):
        for q, pairs in d.items():
            after[(j, q)] += [(i, r + 1) for i, r in pairs]
    done, left = set(), dict(after)
    while left:
        free = [e for e, before in left.items() if all(b in done for b in before)]
        if not free:
            return True
        for e in free:
            done.add(e)
            del left[e]
    return False


def swap_plan():
    """Two agents swap ends of a corridor (an Apartment0 plan, 5 agents, easy problem 14): agent 0 leaves
    node 1 at time 2 and is at node 2 at time 9; agent 1 is at node 5, beside node 2, at time 6 and
    arrives at node 1 at time 12. Each gets to the shared place before the other arrives there, so
    each waits for the other to *leave* it first."""
    close = np.eye(12, dtype=bool)
    close[2, 5] = close[5, 2] = True
    routes = [[10, 1, 2, 3], [11, 4, 5, 1]]
    times = [[0, 2, 9, 12], [0, 3, 6, 12]]
    return routes, times, [6, 7], [15, 15], close


def test_two_agents_swapping_places_do_not_wait_for_each_other():
    routes, times, goals, goal_times, close = swap_plan()
    deps = plan_dependencies(routes, times, times, goals, goal_times, close)
    assert not wait_cycle(deps, [4, 4])
    assert deps[1] == {3: [(0, 2)]}  # agent 1 heads for node 1 once agent 0 has left node 2, as planned
    # agent 0's wait for agent 1 to leave node 5 (at time 6, after agent 0 sets off at 2) is the one
    # furthest behind in plan time: it now waits only for agent 1 to have left its start
    assert deps[0] == {2: [(1, 0)]}
    # in a controller, both get through at once instead of standing until the order's patience runs out
    wp = {a: np.array([[float(10 * a + n), 0.0] for n in route]) for a, route in enumerate(routes)}
    plans = {f"agent_{a}": AgentPlan(wp[a], np.array([100.0 + a, 0.0]), starts_at_first=True,
                                     after={q: [(f"agent_{i}", r) for i, r in v] for q, v in deps[a].items()})
             for a in range(2)}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=40),
    )
    for _ in range(6):  # every agent stands on the target it heads for at each step
        c.act({a: c.current_goal(a) for a in plans})
    assert c.index == {"agent_0": 4, "agent_1": 4} and c.stats.waits <= 2


def run_teleported(c, plans, steps=60):
    """Drive ``c`` with agents that stand on their current target at every step; an agent at its goal
    after its last waypoint is parked (out of the episode). Returns per agent the step it parked."""
    live, arrived = set(plans), {}
    for t in range(steps):
        if not live:
            break
        obs = {x: c.current_goal(x) for x in sorted(live)}
        c.act(obs)
        for x in sorted(live):
            if c.index[x] == len(plans[x].waypoints) and np.array_equal(obs[x], plans[x].goal):
                arrived[x] = t
                live.discard(x)
    return arrived


def test_an_agent_that_holds_its_parking_for_another_lets_that_one_go_first():
    """The plan sends b through a corridor first, to park at its far end, and a after it (a waits for b
    to arrive); a's route runs past b's goal, so the goal order holds b at its last waypoint until a has
    gone by. The two holds meet: a goes first (traced on Apartment3's held-out hard 5-agent problem 0,
    where both stood until the order's patience ran out and b then parked in the corridor's mouth)."""
    wa = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    wb = np.array([[0.0, 5.0], [2.0, 5.0]])
    plans = {"a": AgentPlan(wa, np.array([6.0, 0.0]), starts_at_first=True, after={2: [("b", 2)]}),
             "b": AgentPlan(wb, np.array([4.0, 1.0]), starts_at_first=True)}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=40),
        goal_order=lambda agent: [("a", 2)] if agent == "b" else [],
    )
    arrived = run_teleported(c, plans, steps=20)
    assert set(arrived) == {"a", "b"} and max(arrived.values()) < 10 and c.stats.waits < 10
    assert plans["a"].after is not None and c._after["a"] == {2: []}  # a no longer waits for b


@pytest.mark.parametrize("c_parks_after_a", [True, False])
def test_holds_that_close_a_cycle_of_three_agents_are_broken_at_once(c_parks_after_a):
    """a waits on b by the plan's order, b on c, and c on a: by the goal order (c holds its parking
    until a has gone by, traced on Apartment3's held-out hard 5-agent problem 0, where three agents at a
    doorway stood for 36 steps until the order's patience ran out) or, given by hand, by the plan's order
    too. The agent the parking one holds for goes first; in a cycle of plan-order waits only, the first
    by name. Without the rule all three stand until the patience (40 steps) runs out."""
    line = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    plans = {"a": AgentPlan(line, np.array([6.0, 0.0]), starts_at_first=True, after={2: [("b", 2)]}),
             "b": AgentPlan(line + [0.0, 5.0], np.array([6.0, 5.0]), starts_at_first=True, after={2: [("c", 2)]}),
             "c": AgentPlan(line[:2] + [0.0, 9.0], np.array([4.0, 9.0]), starts_at_first=True,
                            after=None if c_parks_after_a else {2: [("a", 2)]})}
    order = (lambda agent: [("a", 2)] if agent == "c" else []) if c_parks_after_a else None
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=40),
        goal_order=order,
    )
    arrived = run_teleported(c, plans, steps=60)
    assert set(arrived) == {"a", "b", "c"} and max(arrived.values()) < 10 and c.stats.cycles == 1
    first = "a"  # the one c parks after; in the plan-order cycle the first by name, a too
    assert arrived[first] == min(arrived.values()) and arrived["b"] == max(arrived.values())
    # the wait a gave up is gone for good; b's wait on c ended when c arrived
    assert c._after["a"] == {2: []} and c._after["b"] == {2: []}


def test_an_agent_holding_its_parking_keeps_holding_in_a_cycle_whatever_the_names():
    """b waits on a by the plan's order from the first step, until a has set off for its goal; once a
    is at its last waypoint it holds its parking for b (goal order). The two holds close a cycle: b
    goes first, and a keeps holding although it is first by name (Apartment0, 20 agents, hard problem
    0: breaking such a cycle at the agent first by name parked it before the other had passed, and
    that one was blocked for the rest of the run)."""
    wa = np.array([[0.0, 5.0], [2.0, 5.0], [4.0, 5.0]])
    wb = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    plans = {"a": AgentPlan(wa, np.array([6.0, 1.0]), starts_at_first=True),
             "b": AgentPlan(wb, np.array([6.0, 0.0]), starts_at_first=True, after={1: [("a", 2)]})}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=40),
        goal_order=lambda agent: [("b", 1)] if agent == "a" else [],
    )
    for _ in range(20):  # every agent stands on the target it heads for at each step
        c.act({x: c.current_goal(x) for x in plans})
        if c.index["a"] == 3:  # a set off for its goal: b has passed its target 1
            break
    assert c.index == {"a": 3, "b": 2} and c._gave_up["a"] == set() and c.stats.cycles == 0


def test_a_chain_of_waits_that_does_not_close_a_cycle_is_kept():
    """a waits on b, b on c, and c does not wait: nobody goes out of turn (c, then b, then a)."""
    line = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    plans = {"a": AgentPlan(line, np.array([6.0, 0.0]), starts_at_first=True, after={2: [("b", 2)]}),
             "b": AgentPlan(line + [0.0, 5.0], np.array([6.0, 5.0]), starts_at_first=True, after={2: [("c", 2)]}),
             "c": AgentPlan(line + [0.0, 9.0], np.array([6.0, 9.0]), starts_at_first=True)}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=40),
    )
    arrived = run_teleported(c, plans, steps=60)
    assert arrived["c"] < arrived["b"] < arrived["a"] and c.stats.cycles == 0


def test_hold_cycle_follows_holds_back_to_the_agent_only():
    holds = {"b": "c", "c": "a", "x": "y", "y": "x"}.get
    assert hold_cycle("a", "b", holds, 10) == ["b", "c"]
    assert hold_cycle("a", "x", holds, 10) is None  # a cycle that a is not in
    assert hold_cycle("a", "c", holds, 10) == ["c"]
    assert hold_cycle("a", "b", holds, 1) is None  # longer than the limit
    assert hold_cycle("a", "d", holds, 10) is None  # d holds for nobody


def test_dependencies_follow_the_plan_and_never_wait_in_a_cycle():
    """On random plans every dependency points from an earlier plan arrival to a later one, and the
    controller's waits (departures) have no cycle, so no execution that keeps them deadlocks on them."""
    rng = np.random.default_rng(0)
    cycles_before = 0
    for _ in range(60):
        n, k = 12, 4
        close = rng.random((n, n)) < 0.3
        close |= close.T
        routes = [rng.choice(n, size=rng.integers(2, 6), replace=False).tolist() for _ in range(k)]
        arrivals = [np.cumsum(rng.integers(1, 4, size=len(r))).tolist() for r in routes]
        arrivals = [[a - a_[0] for a in a_] for a_ in arrivals]
        departures = [[a + int(rng.integers(0, 2)) for a in a_] for a_ in arrivals]  # some plans wait
        departures = [[min(d, a_[i + 1] - 1) if i + 1 < len(a_) else d for i, d in enumerate(d_)]
                      for d_, a_ in zip(departures, arrivals)]
        goals = rng.integers(0, n, size=k).tolist()
        goal_arrivals = [d[-1] + int(rng.integers(1, 4)) for d in departures]
        times = [a + [g] for a, g in zip(arrivals, goal_arrivals)]
        deps = plan_dependencies(routes, arrivals, departures, goals, goal_arrivals, close)
        assert not wait_cycle(deps, [len(r) for r in routes])
        for j, d in enumerate(deps):
            for q, pairs in d.items():
                assert q >= 1
                for i, r in pairs:
                    assert i != j and times[i][r] < times[j][q]
        # the same orderings read off arrivals alone (one pair per agent and target, before weakening)
        strict = [{} for _ in range(k)]
        for j in range(k):
            for i in range(k):
                ti, tj = times[i], times[j]
                nodes_i, nodes_j = [*routes[i], goals[i]], [*routes[j], goals[j]]
                for q in range(1, len(nodes_j)):
                    ms = [m for m in range(len(nodes_i)) if close[nodes_i[m], nodes_j[q]] and ti[m] < tj[q]]
                    if ms:
                        m = max(ms)
                        strict[j].setdefault(q, []).append((i, m + 1 if m + 1 < len(ti) and ti[m + 1] < tj[q] else m))
        cycles_before += wait_cycle(strict, [len(r) for r in routes])
    assert cycles_before > 0  # random plans do make such cycles; the weakening removed every one


def test_proximity_relation_exempts_starts_and_goals_among_themselves():
    D = np.full((7, 7), 9.0)
    D[3, 4] = D[5, 6] = D[0, 3] = 1.0  # start-start, goal-goal, buffer-start
    close = proximity_relation(D, 1.5, n_buffer=3, n_agents=2)
    assert not close[3, 4] and not close[5, 6] and close[0, 3] and close[3, 0] and close.diagonal()[:3].all()


def line_distance(obs, goal):
    return np.abs(np.asarray(obs, float) - np.asarray(goal, float)).sum(axis=-1)


def still(obs, goal):
    return np.zeros((len(obs), 2), np.float32)


def test_the_controller_waits_for_the_agent_ahead_and_gives_up_on_one_that_does_not_move():
    wp = np.array([[0.0, 0.0], [5.0, 0.0], [9.0, 0.0]])
    plans = {"a": AgentPlan(wp, np.array([12.0, 0.0]), starts_at_first=True),
             "b": AgentPlan(wp[:2] + [0.0, 1.0], np.array([20.0, 1.0]), starts_at_first=True,
                            after={1: [("a", 2)]})}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=5),
    )
    obs = {"a": wp[0], "b": wp[0] + [0.0, 1.0]}
    c.act(obs)
    assert c.index["b"] == 0 and c.stats.holding["b"] == "wait:a"  # a has not reached its waypoint 2
    assert c.stats.activity == {"a": "drive", "b": "order"}
    c.act({"a": wp[1], "b": obs["b"]})
    assert c.index["a"] == 2 and c.index["b"] == 0
    c.act({"a": wp[2], "b": obs["b"]})  # a reached waypoint 2: b may go
    assert c.index["b"] == 1 and c.stats.holding["b"] is None
    # patience: b waits on a, which stays where it is; after order_patience steps b goes anyway
    plans["b"] = AgentPlan(wp[:2] + [0.0, 1.0], np.array([20.0, 1.0]), starts_at_first=True, after={1: [("a", 2)]})
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=5),
    )
    waited = 0
    while c.index["b"] == 0 and waited < 20:
        c.act({"a": wp[0] + [0.0, 3.0], "b": obs["b"]})
        waited += 1
    assert 5 <= waited <= 7 and c.index["b"] == 1
    # an agent that has arrived (no longer live) releases the agents waiting on it, and so does a new plan
    plans["b"] = AgentPlan(wp[:2] + [0.0, 1.0], np.array([20.0, 1.0]), starts_at_first=True, after={1: [("a", 2)]})
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None),
    )
    c.act({"b": obs["b"]})
    assert c.index["b"] == 1
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None),
    )
    c.set_plans({"a": AgentPlan(wp[:1], np.array([0.0, 5.0]))})
    c.act({"a": wp[0], "b": obs["b"]})
    assert c.index["b"] == 1
    with pytest.raises(KeyError, match="unknown agents"):
        c.set_plans({"z": plans["a"]})


def test_an_agent_does_not_yield_to_one_that_waits_for_it():
    """A waits (plan order) until B has passed; B is close by and A has the yield priority (lower
    index, same lag). B must go: yielding to an agent that stands still for it deadlocks both
    until the order's patience runs out (seen in 5-agent apartment runs, again at every waypoint)."""
    plans = {"a": AgentPlan(np.array([[0.0, 0.0], [5.0, 0.0]]), np.array([9.0, 0.0]), starts_at_first=True,
                            after={1: [("b", 1)]}),
             "b": AgentPlan(np.array([[0.0, 1.0], [5.0, 1.0]]), np.array([9.0, 1.0]), starts_at_first=True)}
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=3.0, stuck_window=None, order_patience=50),
    )
    for _ in range(3):
        act = c.act({"a": np.array([0.0, 0.0]), "b": np.array([0.0, 1.0])})
    assert c.stats.holding == {"a": "wait:b", "b": None} and c.stats.yields == 0
    assert set(act) == {"a", "b"} and c.index["a"] == 0
    c.act({"a": np.array([0.0, 0.0]), "b": np.array([5.0, 1.0])})  # b reached its waypoint: a may go
    assert c.index["a"] == 1 and c.stats.holding["a"] is None
    # two agents that both move still yield: the lower priority stands still
    c = WaypointController(
        still, line_distance,
        {"a": AgentPlan(np.zeros((0, 2)), np.array([9.0, 0.0])),
                                                  "b": AgentPlan(np.zeros((0, 2)), np.array([9.0, 1.0]))},
        config=ControllerConfig(reach_threshold=0.5, safety_radius=3.0, stuck_window=None),
    )
    c.act({"a": np.array([0.0, 0.0]), "b": np.array([0.0, 1.0])})
    assert c.stats.holding == {"a": None, "b": "yield:a"} and c.stats.activity == {"a": "drive", "b": "yield"}


def test_an_agent_that_hovers_away_from_its_target_counts_as_stuck_and_replans():
    wp = np.array([[0.0, 0.0], [5.0, 0.0]])
    asked = []

    def replan(agent, ob, plan):
        asked.append(agent)
        return AgentPlan(np.array([ob]), plan.goal, starts_at_first=True)

    c = WaypointController(
        still, line_distance, {"a": AgentPlan(wp, np.array([9.0, 0.0]), starts_at_first=True)},
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=4, stuck_tolerance=0.01,
                                progress_patience=10, escape_steps=1, skip_after=2),
        replan=replan,
    )
    for t in range(60):  # it moves (never stuck by the window rule) but comes no closer to waypoint 1
        c.act({"a": np.array([2.0, 3.0 + 0.3 * (7 * t % 5)])})
    assert c.stats.stalls >= 2 and len(asked) >= 1 and c.stats.escapes == c.stats.stalls
    off = WaypointController(
        still, line_distance, {"a": AgentPlan(wp, np.array([9.0, 0.0]), starts_at_first=True)},
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None), replan=replan,
    )
    n_asked = len(asked)
    for t in range(60):
        off.act({"a": np.array([2.0, 3.0 + 0.3 * (7 * t % 5)])})
    assert off.stats.stalls == 0 and off.stats.escapes == 0 and len(asked) == n_asked  # the rule is off by default
    with pytest.raises(ValueError, match="progress_patience"):
        WaypointController(still, line_distance, {}, config=ControllerConfig(progress_patience=0))


@pytest.fixture(scope="module")
def nodes():
    env = gym.make("SafeCentralObstacle-v0")
    u = env.unwrapped
    obs = u.normalize(u.sample_states(300, np.random.default_rng(0))).astype(np.float32)
    env.close()
    return obs


def crossing_run(agent, nodes, hold, slow):
    """Two agents cross the map corner to corner, their routes through the same places; agent_0 moves at
    ``slow`` times the speed its plan assumes. Returns (arrived, contacts, waits on the other agent, steps)."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2, max_cycles=300)
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, c_max=0.5, seed=3, hold=hold)
    obs, _ = env.reset(seed=0, options={"starts": [[4.0, 45.0], [45.0, 4.0]], "goals": [[45.0, 4.0], [4.0, 45.0]]})
    arrived, contacts, waits, steps = set(), 0, 0, 0
    while env.agents:
        actions, _ = policy.predict({a: obs[a] for a in env.agents})
        if "agent_0" in actions:
            actions["agent_0"] = actions["agent_0"] * slow
        obs, _, term, _, infos = env.step(actions)
        steps += 1
        arrived |= {a for a, t in term.items() if t}
        contacts += sum(len(i.get("collided_with", ())) for i in infos.values())
        waits += sum(1 for h in policy.stats.holding.values() if h and h.startswith("wait:"))
    env.close()
    return arrived, contacts, waits, steps


def test_a_slowed_agent_delays_the_other_instead_of_meeting_it(stand_in_models, nodes):
    """agent_0 drives at half the speed the plan assumes: in the plan's order the other agent waits for it
    where the plan sends agent_0 through first; both arrive (no deadlock), with fewer contacts than on the
    plan's clock."""
    agent = stand_in_models["constrained"]
    arrived, contacts, waits, steps = crossing_run(agent, nodes, "order", 0.5)
    assert arrived == {"agent_0", "agent_1"} and waits > 0 and steps < 300
    clock_arrived, clock_contacts, clock_waits, _ = crossing_run(agent, nodes, "waits", 0.5)
    assert clock_waits == 0 and contacts < clock_contacts


def test_panorama_agents_keep_the_plans_order_and_vector_agents_its_clock(stand_in_models, nodes):
    from types import SimpleNamespace

    from gymnasium import spaces

    from agents.search.config import preset_for

    image = spaces.Dict({"observation": spaces.Box(0, 255, (4, 32, 32, 4), np.uint8)})
    assert preset_for(SimpleNamespace(observation_space=image)).controller.hold == "order"
    assert preset_for(stand_in_models["constrained"]).controller.hold == "waits"
    agent = stand_in_models["constrained"]
    assert SearchPolicy.from_models(agent, agent, nodes, d_max=12.0).config.controller.hold == "waits"
    assert SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, hold="order").config.controller.hold == "order"
    with pytest.raises(ValueError, match="hold must be"):
        SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, hold="never")


def test_an_agent_parks_only_after_the_agents_whose_routes_pass_its_goal():
    """goal_order: a stands at its last waypoint; b's route still passes a's goal, so a waits until b has
    reached its target 2; with a b that does not move, a parks after order_patience steps and does not
    wait on b again."""
    plans = {"a": AgentPlan(np.array([[0.0, 0.0]]), np.array([3.0, 0.0]), starts_at_first=True),
             "b": AgentPlan(np.array([[3.0, 5.0], [3.0, 1.0], [3.0, -5.0]]), np.array([3.0, -9.0]),
                            starts_at_first=True)}
    asked = []

    def goal_order(agent):
        asked.append(agent)
        return [("b", 2)] if agent == "a" else []

    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=5),
        goal_order=goal_order,
    )
    a0, b = np.array([0.0, 0.0]), [np.array([3.0, 5.0]), np.array([3.0, 1.0]), np.array([3.0, -5.0])]
    c.act({"a": a0, "b": b[0]})
    assert c.index["a"] == 0 and c.stats.holding["a"] == "wait:b" and "a" in asked
    assert c.stats.activity["a"] == "park"
    c.act({"a": a0, "b": b[1]})  # b is on a's goal now: a still waits
    assert c.index["a"] == 0 and c.index["b"] == 2
    c.act({"a": a0, "b": b[2]})  # b has passed
    assert c.index["a"] == 1 and c.stats.holding["a"] is None
    # a b that stays where it is: a gives up on it after the patience, for good
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None, order_patience=5),
        goal_order=goal_order,
    )
    waited = 0
    while c.index["a"] == 0 and waited < 20:
        c.act({"a": a0, "b": b[0] + [0.0, 3.0]})
        waited += 1
    assert 5 <= waited <= 7 and c.index["a"] == 1 and c._gave_up["a"] == {"b"}
    # without goal_order (the default) a parks at once
    c = WaypointController(
        still, line_distance, plans,
        config=ControllerConfig(reach_threshold=0.5, safety_radius=None, stuck_window=None),
    )
    c.act({"a": a0, "b": b[0]})
    assert c.index["a"] == 1


def test_the_agents_that_must_pass_a_goal_are_read_off_their_remaining_routes(stand_in_models, nodes):
    """SearchPolicy's goal order on a hand-made problem graph of 6 nodes: b's leg 1 -> 2 runs past a's
    goal (5) without either end being near it; c's route ends near it; d's route stays clear; b's target
    index moves on as it drives."""
    from types import SimpleNamespace

    agent = stand_in_models["constrained"]
    policy = SearchPolicy.from_models(agent, agent, nodes[:20], d_max=12.0, hold="order")
    far = 9.0
    D = np.full((7, 7), far)
    np.fill_diagonal(D, 0.5)
    D[1, 2] = D[2, 1] = 4.0  # the leg 1 -> 2
    D[1, 5] = D[5, 1] = D[5, 2] = D[2, 5] = 2.7  # a's goal 5 lies on its way: 5.4 <= 4 + radius
    D[3, 5] = D[5, 3] = 1.0  # node 3 is near a's goal
    problem = SimpleNamespace(D=D, n_buffer=5)
    policy.planner = policy.planner.with_options(proximity_radius=1.5)
    routes = {"a": [0], "b": [0, 1, 2], "c": [0, 3], "d": [0, 4]}
    policy.episode = Episode(agents=list(routes))
    for a, g in zip(routes, [5, 6, 6, 6]):
        policy.episode.states[a] = AgentState(goal=np.zeros(2), route=routes[a], problem=problem, goal_id=g)
    policy.controller = SimpleNamespace(index={"a": 1, "b": 0, "c": 1, "d": 0})
    # b must reach target 2 (the end of the leg that passes the goal); c must leave node 3 (its goal, 3)
    assert policy._goal_blockers("a") == [("b", 2), ("c", 2)]
    policy.controller.index["b"] = 3  # b heads for its own goal now, past a's
    assert policy._goal_blockers("a") == [("c", 2)]
