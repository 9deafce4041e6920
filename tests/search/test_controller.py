"""The waypoint controller on the PettingZoo env, with a stand-in policy and stand-in distances."""
import numpy as np
import pytest

import safe_mapf_envs
from agents.search.config import ControllerConfig
from agents.search.execution.controller import AgentPlan, WaypointController
from agents.search.execution.stats import ACTIVITIES

SIZE = 55.0


def straight_policy(obs, goal):
    """Head straight for the goal at full speed (a stand-in for the learned policy)."""
    return np.clip((goal - obs) * SIZE, -1.0, 1.0)


def euclid_steps(obs, goal):
    """Stand-in for the critic: Euclidean distance in world units."""
    return np.linalg.norm((np.asarray(goal) - np.asarray(obs)) * SIZE, axis=-1)


def run(env, ctrl, limit=300):
    obs, infos = env.reset(options=env._pinned)
    trail = {a: [infos[a]["position"]] for a in env.agents}
    while env.agents and ctrl.t < limit:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        obs, _, _, _, infos = env.step(actions)
        for a in infos:
            trail[a].append(infos[a]["position"])
    return {a: np.array(t) for a, t in trail.items()}


def make_env(starts, goals):
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=len(starts))
    env._pinned = {"starts": starts, "goals": goals}
    return env


def test_agent_visits_its_waypoints_around_the_block():
    env = make_env([(5.0, 27.5)], [(50.0, 27.5)])
    wps = np.array([[10.0, 10.0], [45.0, 10.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": AgentPlan(wps, np.array([50, 27.5], np.float32) / SIZE)},
        config=ControllerConfig(reach_threshold=1.0),
    )
    trail = run(env, ctrl)["agent_0"]
    assert np.linalg.norm(trail[-1] - [50, 27.5]) <= 1.0
    for w in wps * SIZE:  # it passed close to each waypoint, so it went around the block
        assert np.min(np.linalg.norm(trail - w, axis=1)) <= 1.0 + 1e-6
    assert trail[:, 1].min() < 12.0


def test_agent_waits_for_its_planned_departure_time():
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    wp = np.array([[10.0, 5.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps,
        {"agent_0": AgentPlan(wp, np.array([20, 5], np.float32) / SIZE, depart_times=[30])},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None),
    )
    trail = run(env, ctrl)["agent_0"]
    at_wp = np.linalg.norm(trail - [10, 5], axis=1) < 1.0
    left = np.flatnonzero(at_wp)[-1]
    assert left >= 30 and ctrl.stats.waits > 0
    assert len(trail) - 1 < 50  # then it goes on and arrives


def test_lower_priority_agent_yields_in_a_head_on_encounter():
    env = make_env([(5.0, 45.0), (30.0, 45.0)], [(30.0, 45.5), (5.0, 44.5)])
    goals = np.array([[30, 45.5], [5, 44.5]], np.float32) / SIZE
    plans = {f"agent_{i}": AgentPlan(np.zeros((0, 2), np.float32), goals[i]) for i in range(2)}
    ctrl = WaypointController(straight_policy, euclid_steps, plans, config=ControllerConfig(safety_radius=3.0))
    trails = run(env, ctrl, limit=60)
    n = min(len(trails["agent_0"]), len(trails["agent_1"]))
    d = np.linalg.norm(trails["agent_0"][:n] - trails["agent_1"][:n], axis=1)
    assert ctrl.stats.yields > 0
    # agent_1 held still while agent_0 was near (it has the lower priority on a tie)
    held = np.linalg.norm(np.diff(trails["agent_1"], axis=0), axis=1) < 1e-6
    assert held.any()
    assert d.min() > 0.0


def test_replan_is_called_when_an_agent_falls_behind():
    env = make_env([(5.0, 5.0)], [(50.0, 5.0)])
    calls = []

    def replan(agent, obs, plan):
        calls.append(agent)
        return AgentPlan(np.zeros((0, 2), np.float32), plan.goal)

    wp = np.array([[10.0, 5.0]], np.float32) / SIZE
    stuck = lambda o, g: np.zeros((len(o), 2), np.float32)  # noqa: E731  never moves
    ctrl = WaypointController(
        stuck, euclid_steps, {"agent_0": AgentPlan(wp, np.array([50, 5], np.float32) / SIZE, depart_times=[0])},
        config=ControllerConfig(replan_lag=5, safety_radius=None), replan=replan,
    )
    ctrl.index["agent_0"] = 1  # pretend it left the waypoint at time 0 but makes no progress
    env.reset(options=env._pinned)
    obs = {"agent_0": env.normalize(np.array([5.0, 5.0]))}
    for _ in range(10):
        ctrl.act(obs)
    assert calls == ["agent_0"] and ctrl.stats.replans == 1


def offset_steps(obs, goal):
    """Like a learned critic: never zero, even from an observation to itself (2.5 steps more)."""
    return euclid_steps(obs, goal) + 2.5


def test_the_start_waypoint_counts_as_reached_whatever_the_critic_says():
    """A planner's start node is where the agent stands: with a critic whose distance from an
    observation to itself is above the reach threshold, the agent must still move on."""
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    start = np.array([[5.0, 5.0]], np.float32) / SIZE
    goal = np.array([20, 5], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, offset_steps, {"agent_0": AgentPlan(start, goal, depart_times=[0], starts_at_first=True)},
        config=ControllerConfig(reach_threshold=2.0, safety_radius=None),
    )
    trail = run(env, ctrl, limit=40)["agent_0"]
    assert np.linalg.norm(trail[-1] - [20, 5]) <= 1.0
    # without the flag the agent heads for its own start and never gets closer than 2.5 "steps"
    ctrl = WaypointController(
        straight_policy, offset_steps, {"agent_0": AgentPlan(start, goal, depart_times=[0])},
        config=ControllerConfig(reach_threshold=2.0, safety_radius=None, stuck_window=None),
    )
    trail = run(env, ctrl, limit=40)["agent_0"]
    assert np.linalg.norm(trail[-1] - [20, 5]) > 10.0


def test_the_start_waypoint_still_holds_until_its_departure_time():
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    start = np.array([[5.0, 5.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, offset_steps,
        {"agent_0": AgentPlan(start, np.array([20, 5], np.float32) / SIZE, depart_times=[10],
                                                    starts_at_first=True)},
        config=ControllerConfig(reach_threshold=2.0, safety_radius=None),
    )
    trail = run(env, ctrl, limit=40)["agent_0"]
    np.testing.assert_allclose(trail[:11], np.repeat([[5.0, 5.0]], 11, axis=0), atol=1e-6)
    assert np.linalg.norm(trail[-1] - [20, 5]) <= 1.0 and ctrl.stats.escapes == 0


def wall_pusher(obs, goal):
    """A policy that pushes straight down into the wall below, wherever the goal is."""
    return np.tile(np.array([0.0, -1.0], np.float32), (len(obs), 1))


def test_a_stuck_agent_escapes_with_random_actions_and_gives_up_the_waypoint():
    """Pressed against the wall, the agent's observation stops changing: the controller takes
    random actions instead (reproducibly from its seed) and, stuck twice on the way to the same
    waypoint, moves on to the next target."""
    wp = np.array([[5.0, 0.2]], np.float32) / SIZE  # in the wall: an agent centre never gets within 0.3
    goal = np.array([40, 40], np.float32) / SIZE
    trails = []
    for _ in range(2):
        env = make_env([(5.0, 5.0)], [(40.0, 40.0)])
        ctrl = WaypointController(
            wall_pusher, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
            config=ControllerConfig(reach_threshold=0.1, safety_radius=None), seed=3,
        )
        trails.append(run(env, ctrl, limit=40)["agent_0"])
        assert ctrl.stats.escapes >= 2 and ctrl.stats.skips == 1
        assert ctrl.index["agent_0"] == 1  # now heading for the goal
    np.testing.assert_array_equal(trails[0], trails[1])
    # off: pressed against the wall to the end
    env = make_env([(5.0, 5.0)], [(40.0, 40.0)])
    ctrl = WaypointController(
        wall_pusher, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
        config=ControllerConfig(reach_threshold=0.1, safety_radius=None, stuck_window=None),
    )
    trail = run(env, ctrl, limit=40)["agent_0"]
    assert ctrl.stats.escapes == 0 and np.ptp(trail[10:], axis=0).max() < 1e-3


def test_waiting_on_purpose_is_not_being_stuck():
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    wp = np.array([[5.0, 5.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps,
        {"agent_0": AgentPlan(wp, np.array([20, 5], np.float32) / SIZE, depart_times=[25])},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None),
    )
    run(env, ctrl, limit=60)
    assert ctrl.stats.waits >= 20 and ctrl.stats.escapes == 0


def test_unstick_arguments_are_checked():
    with pytest.raises(ValueError, match="stuck_window"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(stuck_window=0))
    with pytest.raises(ValueError, match="escape_steps"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(escape_steps=0))


def test_a_stuck_agent_asks_for_a_new_plan_when_it_can():
    wp = np.array([[5.0, 0.2], [9.0, 9.0]], np.float32) / SIZE
    goal = np.array([40, 40], np.float32) / SIZE
    seen = []

    def replan(agent, obs, plan):
        seen.append((agent, ctrl.index[agent], obs.copy()))
        return AgentPlan(np.zeros((0, 2), np.float32), plan.goal)

    env = make_env([(5.0, 5.0)], [(40.0, 40.0)])
    ctrl = WaypointController(
        wall_pusher, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
        config=ControllerConfig(reach_threshold=0.1, safety_radius=None), replan=replan,
    )
    run(env, ctrl, limit=30)
    assert ctrl.stats.replans == 1 and ctrl.stats.skips == 0
    agent, index, obs = seen[0]
    assert agent == "agent_0" and index == 0  # it was still heading for the unreachable waypoint
    assert obs[1] * SIZE < 1.0  # asked from where it was stuck, against the wall
    assert len(ctrl.plans["agent_0"].waypoints) == 0 and ctrl.index["agent_0"] == 0


def test_a_waypoint_whose_own_distance_is_above_the_threshold_is_still_reached():
    """A learned distance from a panorama to itself is not zero: with ``self_margin`` a waypoint
    counts as reached below its own predicted distance plus the margin."""
    wp = np.array([[12.0, 5.0]], np.float32) / SIZE
    goal = np.array([12, 25], np.float32) / SIZE
    for margin, arrives in ((0.5, True), (None, False)):
        env = make_env([(5.0, 5.0)], [(12.0, 25.0)])
        ctrl = WaypointController(
            straight_policy, offset_steps, {"agent_0": AgentPlan(wp, goal)},
            config=ControllerConfig(reach_threshold=2.0, self_margin=margin, safety_radius=None, stuck_window=None),
        )
        trail = run(env, ctrl, limit=60)["agent_0"]
        assert (np.linalg.norm(trail[-1] - [12, 25]) <= 1.0) == arrives
        assert ctrl.reach_threshold_of("agent_0") == (np.inf if arrives else 2.0)


def short_stopper(obs, goal):
    """A policy that stops 2 units short of its goal along x (it never closes the last bit)."""
    target = goal - np.array([2.0, 0.0], np.float32) / SIZE
    return np.clip((target - obs) * SIZE, -1.0, 1.0)


def test_an_agent_hovering_beside_its_waypoint_moves_on_after_the_settle_patience():
    wp = np.array([[20.0, 5.0]], np.float32) / SIZE
    goal = np.array([12, 25], np.float32) / SIZE
    results = {}
    for patience in (5, None):
        env = make_env([(5.0, 5.0)], [(12.0, 25.0)])
        ctrl = WaypointController(
            short_stopper, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
            config=ControllerConfig(reach_threshold=1.0, settle_patience=patience, settle_slack=1.5,
                                    safety_radius=None, stuck_window=None),
        )
        trail = run(env, ctrl, limit=80)["agent_0"]
        results[patience] = (ctrl.index["agent_0"], ctrl.stats.settled, trail)
    index, settled, trail = results[5]
    assert index == 1 and settled == 1
    assert trail[-1][1] > 20.0  # it went on towards the goal
    index, settled, trail = results[None]
    assert index == 0 and settled == 0 and trail[-1][1] < 6.0  # hovering 2 units short to the end
    # too far from the waypoint to count as beside it: the rule does not fire
    env = make_env([(5.0, 5.0)], [(12.0, 25.0)])
    ctrl = WaypointController(
        short_stopper, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
        config=ControllerConfig(reach_threshold=0.2, settle_patience=5, settle_slack=1.0, safety_radius=None,
                                stuck_window=None),
    )
    run(env, ctrl, limit=40)
    assert ctrl.index["agent_0"] == 0 and ctrl.stats.settled == 0


def on_course_run(slack, limit=120):
    """An approach waypoint (17, 12) inside a wide reach threshold (16) of the start (14, 27): from the
    start, heading for the goal (45, 12) runs into the central block; from the waypoint it does not.
    Returns the controller, the trail and where the agent stood when it set off for the goal."""
    env = make_env([(14.0, 27.0)], [(45.0, 12.0)])
    wp = np.array([[17.0, 12.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": AgentPlan(wp, np.array([45, 12], np.float32) / SIZE)},
        config=ControllerConfig(reach_threshold=16.0, safety_radius=None, stuck_window=None, advance_slack=slack),
    )
    obs, infos = env.reset(options=env._pinned)
    trail, turned = [infos["agent_0"]["position"]], None
    while env.agents and ctrl.t < limit:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        if turned is None and ctrl.index["agent_0"] == 1:
            turned = trail[-1]
        obs, _, _, _, infos = env.step(actions)
        trail += [infos[a]["position"] for a in infos]
    return ctrl, np.array(trail), turned


def test_a_waypoint_counts_as_reached_only_where_the_agent_is_about_as_near_its_next_target():
    def hits_the_block(trail):
        return trail[np.flatnonzero((trail[:, 0] > 19.0) & (trail[:, 0] < 37.0)), 1].max() > 19.0

    ctrl, trail, turned = on_course_run(None)
    assert np.allclose(turned, [14, 27])  # it turned for the goal at once, from the start
    assert ctrl.stats.off_course == 0 and hits_the_block(trail)
    for slack in (0.0, 1.0):
        ctrl, trail, turned = on_course_run(slack)
        assert np.linalg.norm(trail[-1] - [45, 12]) <= 1.0  # it arrived
        assert ctrl.stats.off_course > 0
        # it set off for the goal only about as near it as the waypoint is (28 units), not before
        assert 28.0 + slack - 1.0 < np.linalg.norm(turned - [45, 12]) <= 28.0 + slack + 1e-3
        assert not hits_the_block(trail)  # it stayed below the block all the way to the goal
    with pytest.raises(ValueError, match="advance_slack must be"):
        on_course_run(-1.0)


def test_a_new_plan_starts_the_on_course_test_afresh():
    """Replanned while it closes in on the waypoint (14, 20), the agent holds for the new plan's
    waypoint (17, 12) as for any: the closest approach it made to the old waypoint, at the same
    index, does not count as having stopped closing in on the new one."""
    env = make_env([(14.0, 27.0)], [(45.0, 12.0)])
    goal = np.array([45, 12], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": AgentPlan(np.array([[14.0, 20.0]], np.float32) / SIZE, goal)},
        config=ControllerConfig(reach_threshold=16.0, safety_radius=None, stuck_window=None, advance_slack=0.0),
    )
    obs, infos = env.reset(options=env._pinned)
    trail, replanned, turned = [infos["agent_0"]["position"]], False, None
    while env.agents and ctrl.t < 120:
        if not replanned and trail[-1][1] <= 22.5:
            ctrl.set_plan("agent_0", AgentPlan(np.array([[17.0, 12.0]], np.float32) / SIZE, goal))
            replanned = True
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        if turned is None and ctrl.index["agent_0"] == 1:
            turned = trail[-1]
        obs, _, _, _, infos = env.step(actions)
        trail += [infos[a]["position"] for a in infos]
    assert replanned and turned is not None
    assert np.linalg.norm(turned - [45, 12]) <= 28.0 + 1e-3  # as near the goal as the new waypoint
    assert np.linalg.norm(trail[-1] - [45, 12]) <= 1.0


def test_the_on_course_test_holds_an_agent_only_while_it_closes_in_on_its_waypoint():
    """A policy that stops 2 units short of the waypoint (20, 5), on the far side from the goal
    (40, 5), never gets as near the goal as the waypoint: once it comes no closer it moves on, two
    steps later, long before it would settle (``settle_patience``) or count as stuck."""
    wp = np.array([[20.0, 5.0]], np.float32) / SIZE
    goal = np.array([40, 5], np.float32) / SIZE
    env = make_env([(5.0, 5.0)], [(40.0, 5.0)])
    ctrl = WaypointController(
        short_stopper, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
        config=ControllerConfig(reach_threshold=3.0, settle_patience=10, advance_slack=0.0, safety_radius=None,
                                stuck_window=4),
    )
    obs, infos = env.reset(options=env._pinned)
    held = moved_on = None
    while env.agents and ctrl.t < 80:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        if held is None and ctrl.stats.off_course:
            held = ctrl.t
        if moved_on is None and ctrl.index["agent_0"] == 1:
            moved_on, escapes = ctrl.t, ctrl.stats.escapes
        obs, _, _, _, infos = env.step(actions)
    assert held is not None and moved_on is not None
    assert 0 < moved_on - held <= 4
    assert ctrl.stats.settled == 0 and escapes == 0
    assert infos["agent_0"]["position"][0] > 30.0  # it went on towards the goal (and stops short of it)


def refuser(obs, goal):
    """A policy that will not move (a constrained policy refusing a goal beside furniture)."""
    return np.zeros((len(obs), 2), np.float32)


def test_a_stuck_leg_is_handed_to_the_fallback_policy():
    goal = np.array([20, 5], np.float32) / SIZE
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    ctrl = WaypointController(
        refuser, euclid_steps, {"agent_0": AgentPlan(goal[None][:0], goal)},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None), fallback_policy=straight_policy, seed=1,
    )
    trail = run(env, ctrl, limit=80)["agent_0"]
    assert np.linalg.norm(trail[-1] - [20, 5]) <= 1.0
    assert ctrl.stats.fallbacks == 1 and ctrl.stats.fallback_steps > 0
    # without it the refusing agent never gets there
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    ctrl = WaypointController(
        refuser, euclid_steps, {"agent_0": AgentPlan(goal[None][:0], goal)},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None), seed=1,
    )
    trail = run(env, ctrl, limit=80)["agent_0"]
    assert np.linalg.norm(trail[-1] - [20, 5]) > 5.0 and ctrl.stats.fallbacks == 0


def test_the_controller_records_what_each_agent_does_on_each_step():
    """ControllerStats.activity: the refusing agent drives (standing), is found stuck and escapes,
    then the fallback drives its leg; holds are named after their reason."""
    goal = np.array([20, 5], np.float32) / SIZE
    env = make_env([(5.0, 5.0)], [(20.0, 5.0)])
    ctrl = WaypointController(
        refuser, euclid_steps, {"agent_0": AgentPlan(goal[None][:0], goal)},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None), fallback_policy=straight_policy, seed=1,
    )
    obs, _ = env.reset(options=env._pinned)
    seen = []
    while env.agents and ctrl.t < 80:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        seen.append(ctrl.stats.activity["agent_0"])
        obs, *_ = env.step(actions)
    assert set(seen) <= set(ACTIVITIES)
    first = {a: seen.index(a) for a in ("drive", "escape", "fallback")}
    assert first["drive"] == 0 < first["escape"] < first["fallback"]
    assert seen.count("escape") >= ctrl.stats.escapes and 0 < seen.count("fallback") <= ctrl.stats.fallback_steps
    assert not {"wait", "order", "park", "clear", "yield"} & set(seen)
    # the kinds of hold
    assert ctrl._activity("agent_0", "wait", False) == "wait"
    assert ctrl._activity("agent_0", "yield:agent_1", False) == "yield"
    assert ctrl._activity("agent_0", "clear:agent_1", False) == "clear"
    assert ctrl._activity("agent_0", "wait:agent_1", False) == "order"
    ctrl._parks_after["agent_0"] = "agent_1"
    assert ctrl._activity("agent_0", "wait:agent_1", False) == "park"
    assert ctrl._activity("agent_0", "wait:agent_2", False) == "order"


def test_the_fallback_drives_only_the_stuck_leg():
    """After the fallback brings the agent to its next waypoint, its own policy drives again."""
    calls = {"main": 0, "fallback": 0}

    def main(obs, goal):
        calls["main"] += 1
        far = np.linalg.norm((goal - obs) * SIZE, axis=-1) > 3.0  # refuses until close
        out = straight_policy(obs, goal)
        out[far & (goal[:, 0] * SIZE < 15)] = 0.0  # ... on the first leg only
        return out

    def fb(obs, goal):
        calls["fallback"] += 1
        return straight_policy(obs, goal)

    wp = np.array([[12.0, 5.0]], np.float32) / SIZE
    goal = np.array([25, 5], np.float32) / SIZE
    env = make_env([(5.0, 5.0)], [(25.0, 5.0)])
    ctrl = WaypointController(
        main, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None), fallback_policy=fb, seed=0,
    )
    trail = run(env, ctrl, limit=80)["agent_0"]
    assert np.linalg.norm(trail[-1] - [25, 5]) <= 1.0
    assert ctrl.stats.fallbacks == 1
    # the fallback drove from the hand-over to the waypoint (7 units at up to 1 a step), no further
    assert 5 <= ctrl.stats.fallback_steps <= 12


def corner_run(retreat, fallback=straight_policy, limit=150, via=None):
    """The approach waypoint (14, 44) lies within a wide reach threshold (18) of the start (14, 27), so it
    counts as reached at once; heading for the goal (45, 27) from the start, the agent is pressed against
    the central block's west face. From the waypoint it passes above the block. ``via``: one more
    waypoint after it (then the goal is (45, 10), below the block)."""
    goal = (45.0, 27.0) if via is None else (45.0, 10.0)
    env = make_env([(14.0, 27.0)], [goal])
    wps = [(14.0, 44.0)] + ([] if via is None else [via])
    plan = AgentPlan(np.array(wps, np.float32) / SIZE, np.array(goal, np.float32) / SIZE)
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": plan},
        config=ControllerConfig(reach_threshold=18.0, safety_radius=None, skip_after=1, retreat=retreat),
        fallback_policy=fallback, seed=0,
    )
    return ctrl, run(env, ctrl, limit=limit)["agent_0"]


@pytest.mark.parametrize("retreat", ["goal", "any"])
def test_a_leg_handed_to_the_fallback_starts_again_from_the_waypoint_it_set_off_from(retreat):
    ctrl, trail = corner_run(retreat=None)
    assert np.linalg.norm(trail[-1] - [45, 27]) > 20.0  # pressed against the block to the end
    assert ctrl.stats.fallbacks == 1 and ctrl.stats.retreats == 0
    ctrl, trail = corner_run(retreat=retreat)
    assert np.linalg.norm(trail[-1] - [45, 27]) <= 1.0  # arrived
    assert ctrl.stats.fallbacks == 1 and ctrl.stats.retreats == 1
    back = np.flatnonzero(np.linalg.norm(trail - [14, 44], axis=1) < 1.0)
    stuck = np.flatnonzero(trail[:, 0] > 18.0)[0]
    assert len(back) and back[0] > stuck  # first pressed against the block, then back at the waypoint
    assert trail[back[0]:, 1].min() > 34.0 or trail[back[0]:, 0].max() > 36.0  # then over the block
    # without a fallback policy nothing is handed over, and nobody goes back
    ctrl, trail = corner_run(retreat=retreat, fallback=None, limit=60)
    assert ctrl.stats.retreats == 0 and trail[:, 1].max() < 30.0


def test_going_back_on_a_leg_before_the_goal_leg_is_for_retreat_any_only():
    """Stuck on its way to the second waypoint (45, 27) behind the block, the agent goes back to the first
    with ``"any"``; with ``"goal"`` it does not (the leg does not end at the goal)."""
    for retreat, went_back in (("goal", 0), ("any", 1)):
        ctrl, _ = corner_run(retreat=retreat, via=(45.0, 27.0), limit=60)
        assert ctrl.stats.fallbacks >= 1 and ctrl.stats.retreats == went_back
    with pytest.raises(ValueError, match="retreat must be"):
        corner_run(retreat=True)


def test_an_agent_stuck_on_its_way_back_asks_for_a_new_plan_which_ends_the_going_back():
    """The wall pusher counts the waypoint (5, 27) reached at once, is pressed against the south wall on
    its way to the goal, goes back (driven by the fallback, which pushes into the same wall), is found
    stuck again and asks for a new plan: that ends the going back, and nobody goes back twice."""
    asked = []

    def replan(agent, obs, plan):
        asked.append((agent in ctrl._back, ctrl.stats.retreats))
        return AgentPlan(np.array([[14.0, 44.0]], np.float32) / SIZE, plan.goal)

    env = make_env([(14.0, 27.0)], [(45.0, 27.0)])
    plan = AgentPlan(np.array([[5.0, 27.0]], np.float32) / SIZE, np.array([45, 27], np.float32) / SIZE)
    ctrl = WaypointController(
        wall_pusher, euclid_steps, {"agent_0": plan},
        config=ControllerConfig(reach_threshold=10.0, safety_radius=None, skip_after=1, retreat="goal"),
        fallback_policy=wall_pusher, seed=0, replan=replan,
    )
    run(env, ctrl, limit=80)
    assert asked and asked[0] == (True, 1)  # stuck while going back: a new plan
    assert ctrl.stats.retreats == 1 and not ctrl._back


def test_settling_needs_the_agent_near_now_not_only_once():
    """An agent that read near once and is now pressed against a wall with its waypoint behind it
    (reading far) has not settled beside the waypoint."""
    wp = np.array([[12.0, 5.0]], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": AgentPlan(wp, np.array([12, 25], np.float32) / SIZE)},
        config=ControllerConfig(reach_threshold=3.0, settle_patience=5, settle_slack=1.5),
    )
    assert not ctrl._settled("agent_0", 0, 3.5)  # closest approach so far, at t = 0
    ctrl.t = 10
    assert not ctrl._settled("agent_0", 0, 15.0)  # far now: not settled
    assert ctrl._settled("agent_0", 0, 3.6) and ctrl.stats.settled == 1  # near now, no closer for 10 steps


def test_with_skip_after_one_a_stuck_leg_goes_to_the_fallback_at_once_and_then_to_a_replan():
    """The panorama setting: found stuck once, the leg is handed to the fallback; stuck again (the
    fallback pushes into the same wall), the agent asks for a new plan. The default (2) spends two
    rounds of escapes before each of those steps."""
    wp = np.array([[5.0, 0.2], [9.0, 9.0]], np.float32) / SIZE
    goal = np.array([40, 40], np.float32) / SIZE

    def counts(skip_after):
        asked = []

        def replan(agent, obs, plan):
            asked.append((ctrl.t, ctrl.stats.fallbacks, ctrl.stats.escapes))
            return AgentPlan(np.zeros((0, 2), np.float32), plan.goal)

        env = make_env([(5.0, 5.0)], [(40.0, 40.0)])
        ctrl = WaypointController(
            wall_pusher, euclid_steps, {"agent_0": AgentPlan(wp, goal)},
            config=ControllerConfig(reach_threshold=0.1, safety_radius=None, skip_after=skip_after), replan=replan,
            fallback_policy=wall_pusher, seed=0,
        )
        run(env, ctrl, limit=60)
        return asked[0]  # (step, fallbacks, escapes) when the first new plan was asked for

    t1, fallbacks1, escapes1 = counts(1)
    t2, fallbacks2, escapes2 = counts(2)
    assert fallbacks1 == fallbacks2 == 1  # the fallback had its turn first either way
    assert (escapes1, escapes2) == (2, 4) and t1 < t2  # the new plan comes after half the escapes, sooner


def push_past_a_parked_agent(escape, seed, sidestep_after=None):
    """agent_0 drives straight at its goal through agent_1, parked at its own goal on the way;
    returns (steps to arrive or None, escapes, agent_0's trail)."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    obs, infos = env.reset(options={"starts": [(5.0, 5.0), (15.0, 5.0)], "goals": [(30.0, 5.0), (15.0, 5.0)]})
    goal = np.array([30, 5], np.float32) / SIZE
    ctrl = WaypointController(
        straight_policy, euclid_steps, {"agent_0": AgentPlan(np.zeros((0, 2), np.float32), goal)},
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None, escape=escape, skip_after=100,
                                sidestep_after=sidestep_after),
        seed=seed,
    )
    trail = [infos["agent_0"]["position"]]
    while "agent_0" in env.agents and ctrl.t < 200:
        actions = ctrl.act({"agent_0": obs["agent_0"]["observation"]})
        if ctrl.t == 1:  # agent_1 stands on its goal: it arrives at the first step and parks there
            actions["agent_1"] = np.zeros(2, np.float32)
        obs, _, _, _, infos = env.step(actions)
        assert "agent_1" not in env.agents  # parked: an immovable obstacle from now on
        trail.append(infos["agent_0"]["position"])
    return (None if "agent_0" in env.agents else ctrl.t), ctrl.stats.escapes, np.array(trail)


def test_a_sidestep_takes_an_agent_past_a_parked_agent_on_its_line():
    """A policy that does not see another agent as an obstacle pushes into it; stepping sideways to
    its push gets it past in one escape, whatever the seed, where random escapes need up to four."""
    random_escapes = []
    for seed in range(5):
        steps, escapes, trail = push_past_a_parked_agent("sidestep", seed)
        assert steps is not None and steps <= 32 and escapes == 1
        moved = np.diff(trail, axis=0)
        across = (np.abs(moved[:, 1]) > 0.9) & (np.abs(moved[:, 0]) < 0.1)  # full steps across the line
        assert across.sum() == 3 and len(set(np.sign(moved[across, 1]))) == 1  # the 3 escape steps, one way
        random_escapes.append(push_past_a_parked_agent("random", seed)[1])
    assert max(random_escapes) >= 2


def test_sidestep_after_turns_the_escapes_of_an_agent_stuck_again_and_again_into_sidesteps():
    random_runs = [push_past_a_parked_agent("random", seed) for seed in range(5)]
    for seed, (steps_r, escapes_r, trail_r) in enumerate(random_runs):
        steps, escapes, trail = push_past_a_parked_agent("random", seed, sidestep_after=100)
        assert (steps, escapes) == (steps_r, escapes_r) and np.array_equal(trail, trail_r)  # never reached
        assert push_past_a_parked_agent("random", seed, sidestep_after=0)[1] == 1  # sidesteps from the first
        steps, escapes, _ = push_past_a_parked_agent("random", seed, sidestep_after=1)
        assert steps is not None and escapes <= 2  # one random escape, then a sidestep gets it past
    assert max(r[1] for r in random_runs) >= 3  # random escapes alone take longer somewhere
    with pytest.raises(ValueError, match="sidestep_after must be"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(sidestep_after=-1))


def test_the_escape_kind_is_checked():
    with pytest.raises(ValueError, match="escape must be"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(escape="spin"))


def test_sidesteps_alternate_sides():
    """Pushed into the wall below, the agent steps along it: one way at its first escape, the
    other way at its second (one side may be blocked), at full speed."""
    wp = np.array([[20.0, 0.2]], np.float32) / SIZE  # in the wall: never reached
    env = make_env([(20.0, 5.0)], [(40.0, 40.0)])
    plan = AgentPlan(wp, np.array([40, 40], np.float32) / SIZE)
    ctrl = WaypointController(
        wall_pusher, euclid_steps, {"agent_0": plan},
        config=ControllerConfig(reach_threshold=0.1, safety_radius=None, escape="sidestep", skip_after=100),
    )
    trail = run(env, ctrl, limit=40)["agent_0"]
    moved = np.diff(trail, axis=0)
    along = moved[np.abs(moved[:, 0]) > 0.9, 0]  # the escape steps, along the wall
    assert ctrl.stats.escapes >= 2 and len(along) >= 3 + 6
    assert np.all(along[:3] == along[0]) and np.all(along[3:9] == -along[0])  # 3 one way, then 6 the other


def clear_goal_run(goal_clearance, zigzags=8, depart=None, after=None, order_patience=40):
    """agent_0 heads for its goal at (20, 5); agent_1 starts 2 units past it and zigzags beside that goal
    (``zigzags`` legs of about 4 steps, within 2.5 units of it) before it drives on to (40, 5); with
    ``depart`` it first waits at its start until that step. Returns the step at which each arrived, the
    distance of agent_1 from agent_0's goal when agent_0 arrived, and the hold reasons seen."""
    env = make_env([(5.0, 5.0), (22.0, 5.0)], [(20.0, 5.0), (40.0, 5.0)])
    g0, g1 = np.array([20, 5], np.float32) / SIZE, np.array([40, 5], np.float32) / SIZE
    wps = np.array([[22, 5]] + [[21.5, 7] if i % 2 == 0 else [21.5, 3] for i in range(zigzags)], np.float32) / SIZE
    plans = {"agent_0": AgentPlan(np.zeros((0, 2), np.float32), g0),
             "agent_1": AgentPlan(wps, g1, depart_times=None if depart is None else [depart] + [0] * zigzags,
                                  starts_at_first=True, after=after)}
    ctrl = WaypointController(
        straight_policy, euclid_steps, plans,
        config=ControllerConfig(reach_threshold=1.0, safety_radius=None, stuck_window=None,
                                goal_clearance=goal_clearance, order_patience=order_patience),
    )
    obs, infos = env.reset(options=env._pinned)
    arrived, gap, held = {}, None, set()
    while env.agents and ctrl.t < 300:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        held |= {v for v in ctrl.stats.holding.values() if v}
        obs, _, term, _, infos = env.step(actions)
        for a, done in term.items():
            if done and a not in arrived:
                arrived[a] = ctrl.t
                if a == "agent_0" and "agent_1" in infos:
                    gap = float(np.linalg.norm(infos["agent_1"]["position"] - [20.0, 5.0]))
    return arrived, gap, held


def test_an_agent_does_not_park_while_another_stands_by_its_goal():
    arrived, gap, held = clear_goal_run(goal_clearance=None)
    assert gap is not None and gap < 3.0  # it parks beside agent_1 (in a corridor it would shut it in)
    arrived, gap, held = clear_goal_run(goal_clearance=3.0)
    assert "clear:agent_1" in held and "agent_1" in arrived
    assert gap is None or gap >= 3.0  # it waited until agent_1 had left


def test_goal_clearance_gives_up_on_an_agent_that_does_not_leave():
    arrived, gap, held = clear_goal_run(goal_clearance=3.0, zigzags=40, order_patience=15)
    assert "clear:agent_1" in held and arrived["agent_0"] < 50 and gap < 3.0


def test_an_agent_standing_nearer_the_others_goal_moves_on_instead_of_waiting():
    """One step of the rule (no env): agent_0 is 4 units from its goal, agent_1 1 unit past that goal.
    agent_0 holds for agent_1, unless it stands nearer agent_1's goal than agent_1 stands to its own
    (then it moves on: it has to clear that goal anyway)."""
    def hold_of_agent_0(goal1):
        g0 = np.array([20, 5], np.float32) / SIZE
        plans = {"agent_0": AgentPlan(np.zeros((0, 2), np.float32), g0),
                 "agent_1": AgentPlan(np.zeros((0, 2), np.float32), np.array(goal1, np.float32) / SIZE)}
        ctrl = WaypointController(
            straight_policy, euclid_steps, plans,
            config=ControllerConfig(reach_threshold=1.0, safety_radius=None, stuck_window=None, goal_clearance=3.0),
        )
        ctrl.act({"agent_0": np.array([16, 5], np.float32) / SIZE, "agent_1": np.array([21, 5], np.float32) / SIZE})
        return ctrl.stats.holding["agent_0"]

    assert hold_of_agent_0((40.0, 5.0)) == "clear:agent_1"
    assert hold_of_agent_0((16.5, 5.5)) is None


def test_goal_clearance_does_not_wait_on_an_agent_held_for_something_else():
    """agent_1 waits for its departure time: waiting for it to leave would only wait with it."""
    arrived, gap, held = clear_goal_run(goal_clearance=3.0, zigzags=0, depart=60)
    assert "clear:agent_1" not in held and arrived["agent_0"] < 30


def test_an_agent_the_plan_holds_for_the_parking_one_goes_first_when_that_one_clears_its_goal():
    """agent_1's plan says: leave after agent_0 has arrived; agent_0 will not park while agent_1 stands
    by its goal. agent_1 goes first instead of both waiting out their patience."""
    arrived, gap, held = clear_goal_run(goal_clearance=3.0, zigzags=0, after={1: [("agent_0", 1)]},
                                        order_patience=100)
    assert {"clear:agent_1", "wait:agent_0"} <= held
    assert gap >= 3.0 and arrived["agent_0"] < 40 and "agent_1" in arrived  # agent_1 had left: no patience spent


def two_on_last_legs(goal0, goal1, **kw):
    """A controller of two agents with no waypoints left, heading for goals at x = ``goal0`` / ``goal1``, y = 5."""
    plans = {a: AgentPlan(np.zeros((0, 2), np.float32), np.array([g, 5], np.float32) / SIZE)
             for a, g in (("agent_0", goal0), ("agent_1", goal1))}
    return WaypointController(straight_policy, euclid_steps, plans,
                              ControllerConfig(reach_threshold=1.0, safety_radius=3.0, stuck_window=None, **kw))


def step(ctrl, p0, p1):
    """One scripted step with the two agents at ``p0`` and ``p1``; who held still, and why."""
    ctrl.act({"agent_0": np.array(p0, np.float32) / SIZE, "agent_1": np.array(p1, np.float32) / SIZE})
    return ctrl.stats.holding


def test_with_goal_clearance_the_agent_by_the_others_goal_goes_first_and_keeps_its_priority():
    """Two close agents on their last legs, agent_1 half a unit from agent_0's goal: agent_0 yields
    (without the rule agent_1 would, by index). Pushed about, the pair keeps that order while close."""
    def controller(clearance):
        return two_on_last_legs(18, 40, goal_clearance=clearance)

    assert step(controller(None), (16, 5), (17.5, 5)) == {"agent_0": None, "agent_1": "yield:agent_0"}
    ctrl = controller(3.0)
    assert step(ctrl, (16, 5), (17.5, 5)) == {"agent_0": "yield:agent_1", "agent_1": None}
    # agent_1 no longer stands by agent_0's goal; a new pair would go by index, this one keeps its order
    assert step(controller(3.0), (16, 5), (14.5, 5))["agent_1"] == "yield:agent_0"
    assert step(ctrl, (16, 5), (14.5, 5)) == {"agent_0": "yield:agent_1", "agent_1": None}
    step(ctrl, (16, 5), (30, 5))  # apart: the pair is forgotten
    assert step(ctrl, (16, 5), (14.5, 5))["agent_1"] == "yield:agent_0"


def test_goal_clearance_is_checked():
    with pytest.raises(ValueError, match="goal_clearance must be"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(goal_clearance=0.0))


def test_with_push_margin_an_agent_pushed_while_it_yields_goes_first_and_keeps_its_priority():
    """agent_1 yields to agent_0 (by index) and is pushed away from its goal: once its distance to the goal has
    grown by more than push_margin while it yields, agent_0 yields instead; the pair keeps that order while
    close, and is forgotten once apart. Without the rule agent_1 stays held however far it is pushed."""
    plain, ctrl = two_on_last_legs(40, 10, push_margin=None), two_on_last_legs(40, 10, push_margin=1.0)
    for c in (plain, ctrl):
        assert step(c, (18, 5), (20, 5)) == {"agent_0": None, "agent_1": "yield:agent_0"}
        assert step(c, (18.8, 5), (20.8, 5))["agent_1"] == "yield:agent_0"  # pushed 0.8: within the margin
    assert step(plain, (19.5, 5), (21.5, 5))["agent_1"] == "yield:agent_0"
    assert step(ctrl, (19.5, 5), (21.5, 5)) == {"agent_0": "yield:agent_1", "agent_1": None}
    assert ctrl.stats.pushed == 1
    assert step(ctrl, (19.0, 5), (20.5, 5)) == {"agent_0": "yield:agent_1", "agent_1": None}  # kept while close
    step(ctrl, (5, 5), (30, 5))  # apart: the pair is forgotten
    assert step(ctrl, (18, 5), (20, 5))["agent_1"] == "yield:agent_0"


def test_push_margin_is_checked():
    with pytest.raises(ValueError, match="push_margin must be"):
        WaypointController(straight_policy, euclid_steps, {}, config=ControllerConfig(push_margin=-1.0))


def test_a_leg_the_drivers_critic_puts_out_of_reach_is_handed_to_the_fallback_at_its_start():
    """The graph's critic made the first leg one edge; the driver's critic reads it far beyond that (it will
    not go there): with ``fallback_beyond`` the fallback drives that leg from its first step, without the
    driver being found stuck first; the next leg, within reach, the driver drives again."""
    wp = np.array([[12.0, 5.0]], np.float32) / SIZE
    goal = np.array([25, 5], np.float32) / SIZE

    def main(obs, goal_):
        out = straight_policy(obs, goal_)
        out[goal_[:, 0] * SIZE < 15] = 0.0  # refuses the first leg
        return out

    def critic(obs, goal_):
        d = euclid_steps(obs, goal_)
        return np.where((goal_[:, 0] * SIZE < 15) & (d > 1.5), 40.0, d)

    arrivals = {}
    for beyond in (None, 20.0):
        env = make_env([(5.0, 5.0)], [(25.0, 5.0)])
        ctrl = WaypointController(
            main, critic, {"agent_0": AgentPlan(wp, goal)},
            config=ControllerConfig(reach_threshold=1.0, safety_radius=None, fallback_beyond=beyond),
            fallback_policy=straight_policy, seed=0,
        )
        trail = run(env, ctrl, limit=120)["agent_0"]
        assert np.linalg.norm(trail[-1] - [25, 5]) <= 1.0
        arrivals[beyond] = len(trail)
        if beyond is None:  # found stuck first, then handed over
            assert ctrl.stats.handovers == 0 and ctrl.stats.escapes >= 1 and ctrl.stats.fallbacks == 1
        else:  # handed over at once: never stuck; the fallback drove the 7 units of the first leg only
            assert ctrl.stats.handovers == 1 and ctrl.stats.escapes == 0 and ctrl.stats.fallbacks == 0
            assert 5 <= ctrl.stats.fallback_steps <= 9
    assert arrivals[20.0] < arrivals[None]
    with pytest.raises(ValueError, match="fallback_beyond"):
        WaypointController(main, critic, {"agent_0": AgentPlan(wp, goal)}, config=ControllerConfig(fallback_beyond=0.0))


def test_a_distance_bound_spares_the_critic_far_pairs_and_changes_no_decision():
    """60 agents scattered over the map, some by each other's goals: with a lower bound of the
    steps (here the straight line less half a unit), the yield and clear-goal rules read the critic
    on a small share of the pairs, and every agent holds (or not) as without the bound."""
    rng = np.random.default_rng(4)
    n = 60
    pos = rng.uniform(2, 53, size=(n, 2))
    goals = pos + rng.normal(scale=2.0, size=(n, 2))  # most agents near their goals (the clear-goal rule)
    goals[::3] = rng.uniform(2, 53, size=(len(goals[::3]), 2))
    obs = {f"agent_{i}": (pos[i] / SIZE).astype(np.float32) for i in range(n)}

    def holdings(bound):
        read = []

        def counted(a, b):
            read.append(len(a))
            return euclid_steps(a, b)

        plans = {f"agent_{i}": AgentPlan(np.zeros((0, 2), np.float32), (goals[i] / SIZE).astype(np.float32))
                 for i in range(n)}
        ctrl = WaypointController(straight_policy, counted, plans, bound=bound,
                                  config=ControllerConfig(reach_threshold=0.5, safety_radius=3.0, stuck_window=None,
                                                          goal_clearance=3.0))
        ctrl.act(obs)
        return ctrl.stats.holding, sum(read)

    def bound(a, b):
        return np.maximum(np.linalg.norm((a[:, None] - b[None]) * SIZE, axis=-1) - 0.5, 0.0)

    every, read_all = holdings(None)
    near, read_near = holdings(bound)
    assert near == every
    assert any(v and v.startswith("yield") for v in every.values())
    assert any(v and v.startswith("clear") for v in every.values())
    assert read_near < read_all / 10
    with pytest.raises(ValueError, match="bound returned shape"):
        WaypointController(straight_policy, euclid_steps, {"agent_0": AgentPlan(np.zeros((0, 2)), goals[0] / SIZE),
                                                           "agent_1": AgentPlan(np.zeros((0, 2)), goals[1] / SIZE)},
                           bound=lambda a, b: np.zeros(3)).act({"agent_0": obs["agent_0"], "agent_1": obs["agent_1"]})
