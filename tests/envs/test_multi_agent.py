"""The multi-agent suite: PettingZoo checkers, physics between agents, parking, collisions,
cost parity with the single-agent env, determinism, pinned problems and bad input."""
import pickle
import warnings
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, parallel_seed_test, render_test, state_test

import safe_mapf_envs
from safe_mapf_envs import ENV_SPECS, SafeMultiNavigationEnv, multi
from safe_mapf_envs.multi import central_obstacle_v0
from safe_mapf_envs.rendering import agent_colour
from safe_mapf_envs.world import World

VECTOR_IDS = [s.id for s in ENV_SPECS if s.entry_point.endswith("SafeNavigationEnv") and s.obs_type == "vector"]
AGENT_COUNTS = [1, 5, 20]


@pytest.fixture(autouse=True)
def _quiet_checker_warnings():
    # the PettingZoo checkers pass a dummy reset option and remark on Dict observations
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="ignoring unknown reset options")
        warnings.filterwarnings("ignore", message="Observation")
        warnings.filterwarnings("ignore", message="FigureCanvasAgg is non-interactive")
        yield


def still(env):
    return {a: np.zeros(2, np.float32) for a in env.agents}


# --------------------------------------------------------------------- PettingZoo's own tests
@pytest.mark.parametrize("n", AGENT_COUNTS)
def test_parallel_api(n):
    parallel_api_test(central_obstacle_v0.parallel_env(n_agents=n), num_cycles=60)


@pytest.mark.parametrize("n", AGENT_COUNTS)
def test_parallel_seed(n):
    parallel_seed_test(lambda: central_obstacle_v0.parallel_env(n_agents=n, action_noise=0.1), num_cycles=50)


@pytest.mark.parametrize("n", AGENT_COUNTS)
def test_aec_api(n):
    api_test(central_obstacle_v0.env(n_agents=n), num_cycles=30)


def _seeded(mod, seed=0):
    """``mod``'s ``parallel_env`` and ``env``, each reset once with ``seed`` when made and its action
    spaces seeded: PettingZoo's ``max_cycles_test`` resets without a seed, drives random actions and
    counts on most agents living through every step, while a goal drawn within a few steps of its
    start can end that agent's episode early (the test failed now and then)."""
    def seeded(factory):
        def make(**kwargs):
            e = factory(**kwargs)
            e.reset(seed=seed)
            for i, a in enumerate(e.possible_agents):  # the test's random actions too
                e.action_space(a).seed(seed + i)
            return e
        return make
    return SimpleNamespace(parallel_env=seeded(mod.parallel_env), env=seeded(mod.env))


@pytest.mark.parametrize("env_id", sorted(multi.MODULES))
def test_max_cycles_on_every_map(env_id):
    max_cycles_test(_seeded(multi.MODULES[env_id]))


def test_state():
    state_test(central_obstacle_v0.env(n_agents=5), central_obstacle_v0.parallel_env(n_agents=5))


@pytest.mark.parametrize("n", AGENT_COUNTS)
def test_render(n, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")  # the human mode draws through matplotlib; no real display here
    monkeypatch.setenv("DISPLAY", ":test")
    render_test(lambda render_mode=None: central_obstacle_v0.env(n_agents=n, render_mode=render_mode))


def test_every_single_agent_map_has_a_module():
    assert set(VECTOR_IDS) <= set(multi.MODULES)
    # the apartments too: every registered id but the panorama view of a grid map
    assert set(multi.MODULES) == {s.id for s in safe_mapf_envs.ENV_SPECS} - {"SafeCentralObstacleVisual-v0"}
    from safe_mapf_envs.multi import apartment0_v0

    assert apartment0_v0.parallel_env(n_agents=2).obs_type == "panorama"
    for env_id, mod in multi.MODULES.items():
        env = mod.parallel_env(n_agents=2)
        assert env.scenario.layout.name == safe_mapf_envs.env_spec(env_id).layout
        assert env.metadata["name"] == mod.__name__.rsplit(".", 1)[-1]
    # the factories pickle by reference (vectorised runners send them to subprocesses)
    assert pickle.loads(pickle.dumps(central_obstacle_v0.parallel_env)) is central_obstacle_v0.parallel_env


def test_factories_accept_ids_and_inherit_the_map():
    env = safe_mapf_envs.parallel_env("safe_mapf_envs:SafeMaze-v0", n_agents=3, cost_radius=2.0, max_cycles=7)
    assert env.scenario.layout.name == "Maze" and env.field.cost_radius == 2.0 and env.max_cycles == 7
    assert env.possible_agents == ["agent_0", "agent_1", "agent_2"]
    aec = safe_mapf_envs.env("SafeFourRooms-v0", n_agents=2)
    assert aec.unwrapped.scenario.layout.name == "FourRooms"
    assert safe_mapf_envs.raw_env("SafeU-v0", n_agents=2).possible_agents == ["agent_0", "agent_1"]
    with pytest.raises(ValueError, match="unknown env id"):
        safe_mapf_envs.parallel_env("SafeNowhere-v0")
    for kwargs, match in [
        ({"n_agents": 0}, "n_agents"),
        ({"n_agents": 2.5}, "n_agents"),
        ({"max_cycles": 0}, "max_cycles"),
        ({"min_separation": 0.5}, "min_separation"),
        ({"collision_cost": -1.0}, "collision_cost"),
        ({"observe_neighbors": -1}, "observe_neighbors"),
        ({"obs_type": "lidar"}, "obs_type"),
        ({"render_mode": "ansi"}, "render_mode"),
    ]:
        with pytest.raises(ValueError, match=match):
            safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", **kwargs)


# --------------------------------------------------------------------- observations and state
def test_observations_are_single_agent_observations():
    single = gym.make("SafeCentralObstacle-v0").unwrapped
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3)
    starts = [(5.0, 10.0), (50.0, 5.0), (10.0, 50.0)]
    goals = [(50.0, 45.0), (5.0, 50.0), (45.0, 5.0)]
    obs, infos = env.reset(seed=0, options={"starts": starts, "goals": goals})
    for i, agent in enumerate(env.possible_agents):
        assert env.observation_space(agent) == single.observation_space
        assert single.observation_space.contains(obs[agent])
        assert np.allclose(obs[agent]["observation"], np.array(starts[i]) / 55)
        assert np.array_equal(obs[agent]["achieved_goal"], obs[agent]["observation"])
        assert np.allclose(obs[agent]["desired_goal"], np.array(goals[i]) / 55)
        assert np.allclose(infos[agent]["position"], starts[i]) and np.allclose(infos[agent]["goal"], goals[i])
    state = env.state()
    assert env.state_space.contains(state) and state.shape == (12,)
    assert np.allclose(state[:6], np.ravel(starts) / 55) and np.allclose(state[6:], np.ravel(goals) / 55)
    assert np.allclose(env.denormalize(env.normalize(np.array(starts))), starts, atol=1e-4)


def test_single_agent_policy_runs_unchanged_on_every_agent():
    """A goal-seeking policy written for the single-agent observation drives every agent home."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=4)
    starts = [(5.0, 5.0), (5.0, 50.0), (50.0, 5.0), (50.0, 50.0)]
    goals = [(5.0, 15.0), (15.0, 50.0), (50.0, 15.0), (40.0, 50.0)]
    obs, _ = env.reset(options={"starts": starts, "goals": goals})

    def policy(o):  # single-agent greedy policy: observations in, action out
        return np.clip(env.denormalize(o["desired_goal"] - o["observation"]), -1, 1).astype(np.float32)

    done = set()
    for _ in range(20):
        obs, _, term, _, _ = env.step({a: policy(obs[a]) for a in env.agents})
        done |= {a for a, t in term.items() if t}
    assert done == set(env.possible_agents) and env.agents == []


def test_neighbors_are_the_nearest_other_agents_padded():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, observe_neighbors=4)
    starts = np.array([(5.0, 5.0), (5.0, 8.0), (15.0, 5.0)])
    obs, _ = env.reset(options={"starts": starts})
    space = env.observation_space("agent_0")
    assert space["neighbors"].shape == (4, 2) and space.contains(obs["agent_0"])
    nb = obs["agent_0"]["neighbors"]
    assert np.allclose(nb[0], (starts[1] - starts[0]) / 55) and np.allclose(nb[1], (starts[2] - starts[0]) / 55)
    assert not nb[2:].any()  # only two other agents
    # agent_2 at (15, 5): agent_1 at (5, 8) is about 10.4 away, agent_0 at (5, 5) exactly 10
    nb2 = obs["agent_2"]["neighbors"]
    assert np.allclose(nb2[0], (starts[0] - starts[2]) / 55) and np.allclose(nb2[1], (starts[1] - starts[2]) / 55)


# --------------------------------------------------------------------- reset: pinned and sampled problems
@pytest.mark.parametrize(
    "options, match",
    [
        ({"starts": [(5.0, 5.0), (27.0, 27.0), (50.0, 50.0)]}, "start of agent_1 .* inside an obstacle"),
        ({"goals": [(5.0, 5.0), (9.0, 9.0), (60.0, 5.0)]}, "goal of agent_2 .* outside"),
        ({"starts": [(5.0, 5.0), (np.nan, 9.0), (50.0, 50.0)]}, "start of agent_1 must be finite"),
        ({"starts": [(5.0, 5.0), (9.0, 9.0)]}, r"one \(x, y\) pair per agent"),
        ({"starts": [(5.0, 5.0), (9.0, 9.0), (5.6, 5.4)]}, "starts of agent_0 and agent_2 .* overlap"),
        ({"goals": [(5.0, 5.0), (5.0, 5.0), (50.0, 5.0)]}, "goals of agent_0 and agent_1"),
        ({"starts": "here"}, "per agent"),
        ({"goal_distance": (10.0, 5.0)}, "band"),
    ],
)
def test_bad_reset_options_name_the_agent(options, match):
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3)
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


def test_unknown_reset_option_warns():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="teleport"):
            env.reset(seed=0, options={"teleport": True})


def test_sampled_starts_and_goals_keep_their_distance():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=50, min_separation=2.5)
    for seed in range(3):
        _, infos = env.reset(seed=seed)
        for key in ("position", "goal"):
            p = np.array([infos[a][key] for a in env.possible_agents])
            assert env.scenario.is_free(p).all()
            d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(50) * 1e9
            assert d.min() >= 2.5
    with pytest.raises(ValueError, match="n_agents=200 cannot fit on CenterDot: its capacity is 59 agents"):
        safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=200)


def test_goal_distance_band_and_low_cost_starts():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=4, max_start_cost=0.0)
    _, infos = env.reset(seed=1, options={"goal_distance": (8.0, 12.0)})
    for a in env.possible_agents:
        d = float(env.geodesic_distance(infos[a]["position"], infos[a]["goal"]))
        assert 8.0 <= d <= 12.0 and infos[a]["cost"] == 0.0
    goals = np.array([infos[a]["goal"] for a in env.possible_agents])
    d = np.linalg.norm(goals[:, None] - goals[None], axis=-1) + np.eye(4) * 1e9
    assert d.min() >= env.min_separation
    states = env.sample_states(10, np.random.default_rng(0))
    assert states.shape == (10, 2) and env.scenario.is_free(states).all()


# --------------------------------------------------------------------- step: input handling
@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf], [0.1, 0.2, 0.3], [[0.1, 0.2]], "left", None])
def test_bad_actions_raise_naming_the_agent(bad):
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3)
    env.reset(seed=0)
    actions = still(env)
    actions["agent_1"] = bad
    with pytest.raises(ValueError, match="agent_1: action"):
        env.step(actions)


def test_missing_unknown_and_done_agent_actions():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    env.reset(options={"starts": [(5.0, 5.0), (10.0, 5.0), (15.0, 5.0)],
                       "goals": [(5.5, 5.0), (40.0, 5.0), (50.0, 50.0)]})
    with pytest.raises(ValueError, match=r"missing actions for live agents \['agent_2'\]"):
        env.step({"agent_0": [0, 0], "agent_1": [0, 0]})
    with pytest.raises(ValueError, match=r"unknown agents \['robot_7'\]"):
        env.step({**still(env), "robot_7": [0, 0]})
    with pytest.raises(ValueError, match="dict"):
        env.step([[0, 0]] * 3)
    _, _, term, _, _ = env.step(still(env))  # agent_0 starts within reach of its goal
    assert term == {"agent_0": True, "agent_1": False, "agent_2": False}
    assert env.agents == ["agent_1", "agent_2"]
    # actions for done agents are ignored, even malformed ones
    obs, rew, term, trunc, infos = env.step({**still(env), "agent_0": "whatever"})
    assert set(obs) == set(rew) == set(term) == set(trunc) == set(infos) == {"agent_1", "agent_2"}


def test_out_of_range_actions_are_clipped_and_rewards_are_minus_one():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    env.reset(options={"starts": [(5.0, 5.0), (5.0, 50.0)], "goals": [(50.0, 5.0), (50.0, 50.0)]})
    _, rew, _, _, infos = env.step({"agent_0": np.array([5.0, 0.0]), "agent_1": [-0.0, -7.0]})
    assert infos["agent_0"]["position"] == pytest.approx([6.0, 5.0], abs=1e-6)
    assert infos["agent_1"]["position"] == pytest.approx([5.0, 49.0], abs=1e-6)
    assert rew == {"agent_0": -1.0, "agent_1": -1.0}


def test_max_cycles_truncates_everyone_and_the_episode_ends():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, max_cycles=5)
    env.reset(seed=0)
    for t in range(5):
        _, _, term, trunc, _ = env.step(still(env))
        assert all(trunc.values()) == (t == 4) and not any(term.values())
    assert env.agents == []
    assert env.step({}) == ({}, {}, {}, {}, {})
    assert safe_mapf_envs.parallel_env("SafeCentralObstacle-v0").max_cycles == 300


# --------------------------------------------------------------------- physics, cost, collisions
def test_cost_and_motion_match_the_single_agent_env():
    single = gym.make("SafeCentralObstacle-v0", max_episode_steps=100).unwrapped
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1)
    problem = {"start": (18.0, 24.0), "goal": (50.0, 50.0)}
    _, info_s = single.reset(options=problem)
    _, infos = env.reset(options={"starts": [problem["start"]], "goals": [problem["goal"]]})
    assert infos["agent_0"]["cost"] == info_s["cost"] > 0
    for a in np.random.default_rng(0).uniform(-1.2, 1.2, size=(40, 2)).astype(np.float32):
        _, _, _, _, info_s = single.step(a)
        _, _, _, _, infos = env.step({"agent_0": a})
        assert np.array_equal(infos["agent_0"]["position"], info_s["position"])
        assert infos["agent_0"]["cost"] == info_s["cost"]


def test_head_on_collision_is_counted_and_costed():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, collision_cost=0.5)
    env.reset(options={"starts": [(5.0, 5.0), (7.5, 5.0), (50.0, 50.0)],
                       "goals": [(50.0, 5.0), (5.0, 50.0), (5.0, 45.0)]})
    _, _, _, _, infos = env.step({"agent_0": [1, 0], "agent_1": [-1, 0], "agent_2": [0, 0]})
    for me, other in (("agent_0", "agent_1"), ("agent_1", "agent_0")):
        assert infos[me]["collisions"] == 1 and infos[me]["collided_with"] == [other]
        assert infos[me]["cost"] == pytest.approx(infos[me]["obstacle_cost"] + 0.5)
    assert infos["agent_2"]["collisions"] == 0 and infos["agent_2"]["collided_with"] == []
    assert infos["agent_2"]["cost"] == infos["agent_2"]["obstacle_cost"]
    p0, p1 = infos["agent_0"]["position"], infos["agent_1"]["position"]
    assert np.linalg.norm(p0 - p1) >= 1.0 - 0.01  # they stopped at contact instead of passing through
    assert p0[0] < p1[0]


def test_parked_agent_stays_put_and_blocks_others():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    env.reset(options={"starts": [(10.0, 5.0), (5.0, 5.0)], "goals": [(10.5, 5.0), (15.0, 5.0)]})
    _, _, term, _, _ = env.step({"agent_0": [0, 0], "agent_1": [1, 0]})
    assert term == {"agent_0": True, "agent_1": False} and env.parked.tolist() == [True, False]
    parked_at = env.positions[0].copy()
    hits = 0
    for _ in range(10):  # agent_1 drives straight into the parked agent
        _, _, _, _, infos = env.step({"agent_1": [1, 0]})
        hits += infos["agent_1"]["collisions"]
        assert infos["agent_1"]["collided_with"] in ([], ["agent_0"])
    assert np.array_equal(env.positions[0], parked_at)
    assert hits > 0 and env.positions[1][0] <= parked_at[0] - 1.0 + 0.01


@settings(max_examples=12, deadline=None)
@given(
    env_id=st.sampled_from(["SafeCentralObstacle-v0", "SafeMaze-v0", "SafeFourRooms-v0", "SafeTunnel-v0"]),
    n=st.integers(2, 12),
    seed=st.integers(0, 10_000),
    crowd=st.booleans(),
)
def test_agents_never_enter_obstacles_or_each_other(env_id, n, seed, crowd):
    env = safe_mapf_envs.parallel_env(env_id, n_agents=n, goal_threshold=0.3)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    field, r = env.field, env.scenario.agent_radius
    w, h = env.world_size
    target = env.sample_states(1, rng)[0]
    parked_at = {}
    for _ in range(40):
        if not env.agents:
            break
        if crowd:  # everyone pushes towards one point: the hardest case for the contact solver
            pos = env.positions
            acts = {a: 1.5 * (target - pos[env.agent_name_mapping[a]]) for a in env.agents}
        else:
            acts = {a: rng.uniform(-3, 3, 2) for a in env.agents}
        env.step(acts)
        p = env.positions
        assert (field.distance(p) >= r - 0.01).all()
        assert (p >= r - 0.01).all() and (p[:, 0] <= w - r + 0.01).all() and (p[:, 1] <= h - r + 0.01).all()
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(n) * 1e9
        assert d.min() >= 2 * r - 0.01
        for i in np.flatnonzero(env.parked):
            parked_at.setdefault(i, p[i].copy())
            assert np.array_equal(p[i], parked_at[i])


def _episode(env, seed, actions_seed, steps=30):
    obs, infos = env.reset(seed=seed)
    rng = np.random.default_rng(actions_seed)
    out = [(obs, infos)]
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}))
    return out


def _same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return type(a) is type(b) and a == b


def test_same_seed_same_actions_same_trajectories_bit_for_bit():
    kwargs = dict(n_agents=12, action_noise=0.1, observe_neighbors=2, collision_cost=1.0)
    env_a = safe_mapf_envs.parallel_env("SafeTunnel-v0", **kwargs)
    env_b = safe_mapf_envs.parallel_env("SafeTunnel-v0", **kwargs)
    first = _episode(env_a, 5, 0)
    assert _same(first, _episode(env_b, 5, 0))
    assert _same(first, _episode(env_a, 5, 0))  # the same instance again: the space is rebuilt
    assert not _same(first, _episode(env_a, 6, 0))


def test_batched_world_matches_body_by_body_world():
    env = safe_mapf_envs.parallel_env("SafeTunnel-v0", n_agents=10)
    env.reset(seed=3)
    sc, starts = env.scenario, env.positions
    acts = np.random.default_rng(0).uniform(-1.5, 1.5, size=(60, 10, 2))
    runs = []
    for batched in (True, False):
        world = World(sc.size, sc.boxes, starts, sc.agent_radius, 4)
        assert world._batched
        world._batched = batched
        steps = []
        for t, a in enumerate(acts):
            if t == 20:
                world.park(4)
            trace, contacts = world.step(a)
            steps.append((trace.copy(), sorted(contacts)))
        runs.append((steps, world.positions()))
    (steps_a, end_a), (steps_b, end_b) = runs
    assert all(np.array_equal(x[0], y[0]) and x[1] == y[1] for x, y in zip(steps_a, steps_b))
    assert np.array_equal(end_a, end_b) and sum(len(s[1]) for s in steps_a) > 0


# --------------------------------------------------------------------- rendering
def test_rgb_render_shows_agents_waypoints_and_collisions():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        env.render()
    env.reset(options={"starts": [(5.0, 5.0), (50.0, 5.0), (5.0, 50.0)],
                       "goals": [(50.0, 50.0), (10.0, 40.0), (40.0, 10.0)]})
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    scale = img.shape[1] / 55
    for i, (x, y) in enumerate([(5.0, 5.0), (50.0, 5.0), (5.0, 50.0)]):
        assert tuple(img[int(y * scale), int(x * scale)]) == agent_colour(i)
    before = img.copy()
    env.set_waypoints({"agent_1": np.array([[45.0, 15.0], [30.0, 45.0]])})
    with_wps = env.render()
    assert (with_wps != before).any()
    env.set_waypoints(None)
    assert np.array_equal(env.render(), before)
    with pytest.raises(ValueError, match="unknown agent"):
        env.set_waypoints({"agent_9": [[1.0, 1.0]]})
    with pytest.raises(ValueError, match="one entry per agent"):
        env.set_waypoints([[[1.0, 1.0]]])
    # two agents bump: a collision marker (black cross) appears between them
    env.reset(options={"starts": [(10.0, 45.0), (12.5, 45.0), (50.0, 5.0)]})
    env.render()
    _, _, _, _, infos = env.step({"agent_0": [1, 0], "agent_1": [-1, 0], "agent_2": [0, 0]})
    assert infos["agent_0"]["collisions"] == 1
    img = env.render()
    mid = 0.5 * (infos["agent_0"]["position"] + infos["agent_1"]["position"])
    patch = img[int(mid[1] * scale) - 8:int(mid[1] * scale) + 9, int(mid[0] * scale) - 8:int(mid[0] * scale) + 9]
    assert (patch.sum(-1) == 0).any()


def test_human_mode_without_display_names_the_problem(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(UserWarning, match="needs a display"):
        env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", render_mode="human")
    env.reset(seed=0)
    env.step({a: np.zeros(2, np.float32) for a in env.agents})
    assert env.render() is None


def test_env_class_is_exported():
    assert isinstance(central_obstacle_v0.parallel_env(), SafeMultiNavigationEnv)
