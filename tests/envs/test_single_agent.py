"""The single-agent suite: API checkers, determinism, physics, cost, bad input, GoalEnv methods."""
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from safe_mapf_envs import ENV_SPECS, SafetyGymnasiumStyle
from safe_mapf_envs.cost import ObstacleField

SINGLE_IDS = [s.id for s in ENV_SPECS if s.entry_point.endswith("SafeNavigationEnv")]


@pytest.mark.parametrize("env_id", SINGLE_IDS)
def test_gymnasium_and_sb3_checkers(env_id):
    env = gym.make(env_id)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(gym.make(env_id).unwrapped, warn=True)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    _, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
    assert isinstance(info["cost"], float) and info["cost"] >= 0


def test_make_with_module_prefix_and_time_limit():
    env = gym.make("safe_mapf_envs:SafeCentralObstacle-v0")
    assert env.spec.max_episode_steps == 20
    env.reset(seed=0, options={"start": (5.0, 5.0), "goal": (50.0, 50.0)})
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
        steps += 1
        assert not terminated
    assert steps == 20
    long_env = gym.make("SafeCentralObstacle-v0", max_episode_steps=300)
    assert long_env.spec.max_episode_steps == 300


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    traj = [obs["observation"].copy()]
    costs = []
    for a in actions:
        obs, _, terminated, truncated, info = env.step(a)
        traj.append(obs["observation"].copy())
        costs.append(info["cost"])
        if terminated or truncated:
            break
    return np.array(traj), np.array(costs)


@pytest.mark.parametrize("env_id", ["SafeCentralObstacle-v0", "SafeMaze-v0"])
def test_same_seed_same_trajectory_bit_for_bit(env_id):
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, size=(20, 2)).astype(np.float32)
    env_a, env_b = gym.make(env_id, action_noise=0.1), gym.make(env_id, action_noise=0.1)
    ta, ca = _rollout(env_a, 7, actions)
    tb, cb = _rollout(env_b, 7, actions)
    assert np.array_equal(ta, tb) and np.array_equal(ca, cb)
    # a second episode on the same env instance reproduces the first one too
    tc, cc = _rollout(env_a, 7, actions)
    assert np.array_equal(ta, tc) and np.array_equal(ca, cc)
    td, _ = _rollout(env_a, 8, actions)
    assert not np.array_equal(ta, td)


@settings(max_examples=25, deadline=None)
@given(
    env_id=st.sampled_from(["SafeCentralObstacle-v0", "SafeMaze-v0", "SafeFourRooms-v0", "SafeSpiral-v0"]),
    seed=st.integers(0, 10_000),
    actions=st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=1, max_size=40),
)
def test_random_actions_never_enter_obstacles(env_id, seed, actions):
    env = gym.make(env_id, max_episode_steps=1000).unwrapped
    env.reset(seed=seed)
    field, radius = env.field, env.scenario.agent_radius
    w, h = env.world_size
    for a in actions:
        _, _, terminated, _, info = env.step(np.array(a, np.float32))
        p = info["position"]
        # the centre keeps (almost) a full radius from every obstacle and from the boundary
        assert field.distance(p) >= radius - 0.01
        assert radius - 0.01 <= p[0] <= w - radius + 0.01 and radius - 0.01 <= p[1] <= h - radius + 0.01
        if terminated:
            break


def test_agent_slides_along_wall():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    # the block covers [20, 35] x [20, 35]; push right-and-down into its left face
    env.reset(seed=0, options={"start": (18.0, 25.0), "goal": (5.0, 5.0)})
    for _ in range(5):
        _, _, _, _, info = env.step(np.array([1.0, 1.0], np.float32))
    x, y = info["position"]
    assert x == pytest.approx(19.5, abs=0.02)  # stopped by the face, one radius away
    assert y > 29.0  # still moved along the wall


def brute_force_cost(p, boxes, r):
    """Distance by dense sampling of every box boundary, then the paper's eq. 5."""
    best = np.inf
    t = np.linspace(0, 1, 20001)
    for x0, y0, x1, y1 in boxes:
        edges = [
            np.stack([x0 + t * (x1 - x0), np.full_like(t, y0)], 1),
            np.stack([x0 + t * (x1 - x0), np.full_like(t, y1)], 1),
            np.stack([np.full_like(t, x0), y0 + t * (y1 - y0)], 1),
            np.stack([np.full_like(t, x1), y0 + t * (y1 - y0)], 1),
        ]
        for e in edges:
            best = min(best, np.min(np.linalg.norm(e - p, axis=1)))
    return (2 - 2 * best / r) if best <= r else 0.0


@pytest.mark.parametrize("point", [(10.0, 27.5), (15.0, 15.0), (37.0, 36.0), (27.5, 45.0), (5.0, 5.0), (27.5, 19.0)])
def test_cost_matches_brute_force_reference(point):
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    boxes = env.scenario.boxes
    assert boxes == [(20.0, 20.0, 35.0, 35.0)]
    expected = brute_force_cost(np.array(point), boxes, 10.0)
    assert env.field.cost(np.array(point)) == pytest.approx(expected, abs=1e-3)
    _, info = env.reset(options={"start": point, "goal": (1.0, 1.0)})
    assert info["cost"] == pytest.approx(expected, abs=1e-3)


def test_cost_known_values_and_profiles():
    field = ObstacleField([(20, 20, 35, 35)], (55, 55), cost_radius=10)
    assert field.cost(np.array([15.0, 27.5])) == pytest.approx(1.0)  # h = 5 -> 2 - 1
    assert field.cost(np.array([10.0, 27.5])) == pytest.approx(0.0)  # h = r
    assert field.cost(np.array([2.0, 2.0])) == 0.0
    corner = field.distance(np.array([17.0, 16.0]))
    assert corner == pytest.approx(5.0)  # 3-4-5 triangle to the corner (20, 20)
    cos = ObstacleField([(20, 20, 35, 35)], (55, 55), 10, cost_fn="cosine")
    assert cos.cost(np.array([15.0, 27.5])) == pytest.approx(1.0)
    const = ObstacleField([(20, 20, 35, 35)], (55, 55), 10, cost_fn="constant")
    assert const.cost(np.array([12.0, 27.5])) == 1.0 and const.cost(np.array([5.0, 27.5])) == 0.0
    wall = ObstacleField([], (55, 55), 10, boundary_cost=True)
    assert wall.cost(np.array([2.0, 30.0])) == pytest.approx(1.6)
    with pytest.raises(ValueError, match="cost_fn"):
        ObstacleField([], (5, 5), 1, cost_fn="quadratic")


def test_step_cost_is_max_over_substeps():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    # moving away from the block: the start of the step is the riskiest point
    env.reset(options={"start": (18.0, 27.5), "goal": (1.0, 1.0)})
    _, _, _, _, info = env.step(np.array([-1.0, 0.0], np.float32))
    first_substep = np.array([18.0 - 0.25, 27.5])
    assert info["cost"] == pytest.approx(float(env.field.cost(first_substep)))
    assert info["cost"] > float(env.field.cost(info["position"]))


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf], [0.1, 0.2, 0.3], [[0.1, 0.2]], "left"])
def test_bad_actions_raise(bad):
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)


def test_out_of_range_action_is_clipped():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    env.reset(options={"start": (5.0, 5.0), "goal": (50.0, 50.0)})
    _, _, _, _, info = env.step(np.array([5.0, 0.0]))
    assert info["position"] == pytest.approx([6.0, 5.0], abs=1e-6)


@pytest.mark.parametrize(
    "options, match",
    [
        ({"start": (27.0, 27.0)}, "inside an obstacle"),
        ({"goal": (20.2, 27.0)}, "inside an obstacle"),
        ({"start": (60.0, 5.0)}, "outside"),
        ({"goal": (5.0, -1.0)}, "outside"),
        ({"start": (np.nan, 5.0)}, "finite"),
        ({"start": (1.0, 2.0, 3.0)}, "pair"),
        ({"goal_distance": (10.0, 5.0)}, "band"),
        ({"goal_distance": (500.0, 600.0)}, "no free goal"),
        ({"start": (5.0 + 1j, 5.0)}, "real"),
    ],
)
def test_bad_reset_options_raise(options, match):
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


def test_pinned_problem_and_goal_distance_band():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    obs, info = env.reset(options={"start": (5.0, 10.0), "goal": (50.0, 45.0)})
    assert np.allclose(obs["observation"], [5 / 55, 10 / 55])
    assert np.allclose(obs["desired_goal"], [50 / 55, 45 / 55])
    assert np.allclose(info["position"], [5, 10]) and np.allclose(info["goal"], [50, 45])
    for seed in range(10):
        _, info = env.reset(seed=seed, options={"goal_distance": (8.0, 12.0)})
        d = float(env.geodesic_distance(info["position"], info["goal"]))
        assert 8.0 <= d <= 12.0


def test_low_cost_starts():
    env = gym.make("SafeCentralObstacle-v0", max_start_cost=0.0).unwrapped
    for seed in range(20):
        _, info = env.reset(seed=seed)
        assert info["cost"] == 0.0


def test_geodesic_distance_goes_around_the_block():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    # straight line when visible
    assert float(env.geodesic_distance((5, 5), (5, 50))) == pytest.approx(45.0)
    # around the block: the exact any-angle length via the two corners is about 49.4
    d = float(env.geodesic_distance((5, 27.5), (50, 27.5)))
    exact = 2 * np.hypot(14.5, 8.0) + 16.0
    assert exact <= d <= exact * 1.04
    states = env.sample_states(50, np.random.default_rng(0))
    assert states.shape == (50, 2) and env.scenario.is_free(states).all()


def test_compute_reward_and_terminated_agree_with_step():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    obs, _ = env.reset(options={"start": (5.0, 5.0), "goal": (7.5, 5.0)})
    achieved, desired, rewards, terms, infos = [], [], [], [], []
    for _ in range(4):
        obs, r, terminated, _, info = env.step(np.array([1.0, 0.0], np.float32))
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(r)
        terms.append(terminated)
        infos.append(info)
        if terminated:
            break
    assert terms[-1] and not any(terms[:-1])
    a, d = np.array(achieved), np.array(desired)
    assert np.array_equal(env.compute_reward(a, d, infos), np.array(rewards, np.float32))
    assert np.array_equal(env.compute_terminated(a, d, infos), np.array(terms))
    assert not env.compute_truncated(a, d, infos).any()
    assert env.compute_reward(a[0], d[0], infos[0]) == rewards[0]


def test_safety_gymnasium_style_wrapper():
    env = SafetyGymnasiumStyle(gym.make("SafeCentralObstacle-v0"))
    env.reset(options={"start": (18.0, 27.5), "goal": (1.0, 1.0)})
    obs, reward, cost, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert cost == info["cost"] > 0 and reward == -1.0


def test_rgb_render_draws_agent_goal_and_waypoints():
    env = gym.make("SafeCentralObstacle-v0", render_mode="rgb_array")
    env.reset(options={"start": (5.0, 5.0), "goal": (50.0, 50.0)})
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    scale = img.shape[1] / 55
    assert img[int(27.5 * scale), int(27.5 * scale)].tolist() == [60, 60, 60]  # the block
    agent_px = img[int(5 * scale), int(5 * scale)]
    assert tuple(agent_px) == (31, 119, 180)
    before = img.copy()
    env.unwrapped.set_waypoints(np.array([[10.0, 45.0], [40.0, 50.0]]))
    after = env.render()
    assert (after != before).any()


def test_human_mode_without_display_names_the_problem_and_check_env_runs_headless(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(UserWarning, match="needs a display"):
        env = gym.make("SafeCentralObstacle-v0", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    assert env.render() is None
    env.close()
    with pytest.warns(UserWarning, match="needs a display"):  # it makes the env in every render mode
        gym_check_env(gym.make("SafeCentralObstacle-v0").unwrapped)


def test_parked_agents_stand_on_the_way_immovable_and_in_view():
    """``parked_agents``: the same start and goal as without them, agents drawn on the way that the
    agent cannot push (it stops at contact), shown in its panorama but not in the goal's."""
    with_parked = gym.make("SafeApartment3-v0", parked_agents=2)
    plain = gym.make("SafeApartment3-v0")
    counts = []
    for seed in range(12):
        obs, info = with_parked.reset(seed=seed)
        obs0, info0 = plain.reset(seed=seed)
        np.testing.assert_array_equal(info["position"], info0["position"])
        np.testing.assert_array_equal(obs["desired_goal"], obs0["desired_goal"])
        parked = info["parked"]
        counts.append(len(parked))
        r = with_parked.unwrapped.scenario.agent_radius
        start, goal = info["position"], info["goal"]
        for p in parked:
            assert np.linalg.norm(p - start) > 2 * r and np.linalg.norm(p - goal) > 2 * r
            t = np.dot(p - start, goal - start) / np.dot(goal - start, goal - start)
            assert 1 / 3 <= t <= 2 / 3
        if len(parked):
            assert (obs["observation"] != obs0["observation"]).any()
            # the achieved goal is the place as a goal shows it: without the parked agents
            np.testing.assert_array_equal(obs["achieved_goal"], obs0["observation"])
            # drive straight at the first parked agent: the agent stops at contact, the parked one stays
            for _ in range(30):
                d = parked[0] - info["position"]
                obs, _, term, trunc, info = with_parked.step((d / np.linalg.norm(d)).astype(np.float32))
                if term or trunc:
                    break
            np.testing.assert_array_equal(info["parked"], parked)
            assert np.linalg.norm(info["position"] - parked[0]) >= 2 * r - 0.02
        else:
            np.testing.assert_array_equal(obs["observation"], obs0["observation"])
            np.testing.assert_array_equal(obs["achieved_goal"], obs["observation"])
    assert sum(counts) >= 8 and max(counts) == 2
    assert "parked" not in plain.reset(seed=0)[1]


def test_parked_fraction_mixes_episodes_with_and_without_parked_agents():
    def counts(fraction):
        env = gym.make("SafeApartment0-v0", parked_agents=2, parked_fraction=fraction)
        out = [len(env.reset(seed=seed)[1]["parked"]) for seed in range(40)]
        env.close()
        return out

    assert not any(counts(0.0))
    half, full = counts(0.5), counts(1.0)
    assert sum(c > 0 for c in full) >= 30  # nearly every episode has them
    assert 8 <= sum(c > 0 for c in half) <= 32 and max(half) == 2


def test_parked_agents_is_checked():
    with pytest.raises(ValueError, match="parked_agents"):
        gym.make("SafeApartment0-v0", parked_agents=-1)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="parked_fraction"):
            gym.make("SafeApartment0-v0", parked_agents=1, parked_fraction=bad)
    with pytest.raises(ValueError, match="parked agents"):
        gym.make_vec("SafeCentralObstacle-v0", num_envs=2, vectorization_mode="vector_entry_point", parked_agents=1)
