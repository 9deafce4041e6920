"""What the single- and multi-agent envs share: reset options, input checks, capacity, messages,
``observations_at``, the SB3 checker on the unwrapped env."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial import cKDTree
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import safe_mapf_envs
from safe_mapf_envs import NavigationEnvBase, SafeMultiNavigationEnv, SafeNavigationEnv
from safe_mapf_envs.checks import check_action, plural, show
from safe_mapf_envs.scenario import RANDOM_FILL, NavigationScenario, union_area


def single(env_id="SafeCentralObstacle-v0", **kwargs):
    return gym.make(env_id, **kwargs).unwrapped


def multi(n=3, env_id="SafeCentralObstacle-v0", **kwargs):
    return safe_mapf_envs.parallel_env(env_id, n_agents=n, **kwargs)


def test_both_envs_share_the_base():
    assert isinstance(single(), NavigationEnvBase) and isinstance(multi(), NavigationEnvBase)
    assert issubclass(SafeNavigationEnv, gym.Env) and issubclass(SafeMultiNavigationEnv, NavigationEnvBase)
    # the old import path of check_action keeps working
    from safe_mapf_envs.single_agent import check_action as old_path

    assert old_path is check_action


# --------------------------------------------------------------------- reset options: one rule
@pytest.mark.parametrize("make, good", [
    (single, {"start": (5.0, 5.0), "goal": (50.0, 50.0)}),
    (multi, {"starts": [(5.0, 5.0), (10.0, 5.0), (15.0, 5.0)]}),
])
def test_unknown_reset_options_warn_in_both_envs_and_are_ignored(make, good):
    env = make()
    with pytest.warns(UserWarning, match=r"ignoring unknown reset options \['teleport'\]"):
        obs_a, _ = env.reset(seed=0, options={**good, "teleport": True})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # known keys alone: no warning
        obs_b, _ = env.reset(seed=0, options=good)
    flat = (lambda o: o) if make is single else (lambda o: o["agent_0"])
    assert np.array_equal(flat(obs_a)["observation"], flat(obs_b)["observation"])


@pytest.mark.parametrize("make", [single, multi])
def test_reset_option_warnings_point_to_the_fix(make):
    env = make()
    with pytest.warns(UserWarning, match="'max_start_cost' is a constructor argument"):
        env.reset(seed=0, options={"max_start_cost": 0.1})
    with pytest.warns(UserWarning, match="did you mean 'goal_distance'"):
        env.reset(seed=0, options={"goal_distanse": (5.0, 9.0)})
    with pytest.raises(ValueError, match="options must be a dict"):
        env.reset(seed=0, options="start")


def test_single_agent_keys_in_the_multi_agent_env_get_a_hint():
    with pytest.warns(UserWarning, match="did you mean 'starts' for 'start'"):
        multi().reset(seed=0, options={"start": (5.0, 5.0)})


# --------------------------------------------------------------------- actions
def test_complex_actions_are_rejected():
    env = single()
    env.reset(seed=0)
    for bad in (np.array([0.5 + 0.5j, 0.0]), [1j, 0.0], np.array([0.5, 0.0], dtype=complex)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no ComplexWarning on the way
            with pytest.raises(ValueError, match="action must be real"):
                env.step(bad)
    env = multi()
    env.reset(seed=0)
    actions = {a: np.zeros(2, np.float32) for a in env.agents}
    actions["agent_2"] = np.array([0.5 + 0.1j, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="agent_2: action must be real"):
            env.step(actions)


def test_real_action_types_still_work():
    env = single()
    for a in ([1, 0], np.array([1.0, 0.0], np.float16), (np.float64(1.0), 0), np.array([True, False])):
        env.reset(options={"start": (5.0, 5.0), "goal": (50.0, 50.0)})
        _, _, _, _, info = env.step(a)
        assert info["position"] == pytest.approx([6.0, 5.0], abs=1e-6)


# --------------------------------------------------------------------- sample_states, geodesic_distance
@pytest.mark.parametrize("make", [single, multi])
def test_sample_states_rejects_bad_counts(make):
    env = make()
    for bad in (-1, 2.5, "3", True):
        with pytest.raises(ValueError, match="n must be an integer >= 0"):
            env.sample_states(bad, np.random.default_rng(0))
    assert env.sample_states(0, np.random.default_rng(0)).shape == (0, 2)
    assert env.sample_states(np.int64(3), np.random.default_rng(0)).shape == (3, 2)


@pytest.mark.parametrize("make", [single, multi])
def test_geodesic_distance_rejects_points_off_the_map_or_in_obstacles(make):
    env = make()
    with pytest.raises(ValueError, match=r"a = \(27.5, 27.5\) is inside an obstacle"):
        env.geodesic_distance((27.5, 27.5), (5.0, 5.0))
    with pytest.raises(ValueError, match=r"b\[1\] = \(60.0, 5.0\) lies outside the 55 x 55 world"):
        env.geodesic_distance((5.0, 5.0), [(10.0, 10.0), (60.0, 5.0)])
    with pytest.raises(ValueError, match=r"b\[0, 1\] = \(30.0, 21.0\) is inside an obstacle"):
        env.geodesic_distance((5.0, 5.0), np.array([[[10.0, 10.0], [30.0, 21.0]]]))
    with pytest.raises(ValueError, match="finite"):
        env.geodesic_distance((5.0, 5.0), (np.nan, 5.0))
    with pytest.raises(ValueError, match="one \\(x, y\\) pair"):
        env.geodesic_distance([(5.0, 5.0), (6.0, 6.0)], (9.0, 9.0))
    # closer to the block than an agent's radius is still measured (agents touch walls)
    d = env.geodesic_distance((5.0, 27.5), [(19.8, 27.5), (50.0, 27.5)])
    assert d.shape == (2,) and d[0] == pytest.approx(14.8) and np.isfinite(d).all()


# --------------------------------------------------------------------- messages
def test_messages_show_plain_numbers_and_singular_nouns():
    env = single()
    with pytest.raises(ValueError) as err:
        env.reset(options={"start": (np.float64(60.0), np.float64(5.0))})
    assert "(60.0, 5.0) lies outside" in str(err.value) and "np.float64" not in str(err.value)
    with pytest.raises(ValueError) as err:
        gym.make("SafeCentralObstacle-v0", goal_threshold=np.float64(-1.0))
    assert "got -1.0" in str(err.value) and "np." not in str(err.value)
    one = multi(n=1)
    with pytest.raises(ValueError) as err:
        one.reset(options={"starts": "here"})
    assert "(1 agent)" in str(err.value)
    assert plural(1, "agent") == "1 agent" and plural(2, "agent") == "2 agents"
    assert show(np.array([1.5, np.nan])) == "[1.5, nan]" and show((np.int64(3),)) == "(3,)"


@pytest.mark.parametrize("kwargs, match", [
    ({"substeps": 2.5}, "substeps must be an integer"),
    ({"action_noise": "a lot"}, "action_noise must be a finite number"),
    ({"action_scale": 0}, "action_scale"),
    ({"max_start_cost": -0.5}, "max_start_cost"),
    ({"goal_distance": (9.0, 3.0)}, "goal_distance"),
    ({"cost_radius": np.inf}, "cost_radius"),
    ({"obs_type": "lidar"}, "obs_type"),
    ({"render_mode": "ansi"}, "render_mode"),
])
def test_both_envs_check_their_shared_arguments_alike(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make("SafeCentralObstacle-v0", **kwargs)
    with pytest.raises(ValueError, match=match):
        multi(**kwargs)


# --------------------------------------------------------------------- capacity
def test_union_area_and_capacity_bounds():
    assert union_area([(0, 0, 2, 2), (1, 1, 3, 3), (5, 5, 5, 9)]) == pytest.approx(7.0)
    sc = NavigationScenario("CentralObstacle")
    # discs of radius 1 around positions 2 apart cover at most the 56 x 56 square less the 14 x 14 block
    assert sc.area_around_free(1.0) == pytest.approx(56 * 56 - 14 * 14)
    assert sc.max_agents(2.0) == int((56 * 56 - 14 * 14) / np.pi)
    assert sc.max_agents(1.0) == int((55 * 55 - 15 * 15) / (np.pi * 0.25))
    assert sc.max_agents(2.0, RANDOM_FILL) < sc.max_agents(2.0)
    with pytest.raises(ValueError, match="at least 2 \\* agent_radius"):
        sc.max_agents(0.5)


def test_too_many_agents_are_refused_by_the_constructor_saying_how_many_fit():
    fit = multi(n=1).capacity
    with pytest.raises(ValueError, match=f"n_agents=5000 cannot fit on CentralObstacle: its capacity is {fit} "):
        multi(n=5000)
    # the scenario refuses a count beyond the capacity at once, naming it
    sc = NavigationScenario("CentralObstacle")
    with pytest.raises(ValueError, match=f"could not place {fit + 1} starts .* its capacity is {fit}"):
        sc.sample_separated(fit + 1, 2.0, np.random.default_rng(0), what="start")
    # pinned starts with sampled goals: the goals fit as well
    grid = np.stack(np.meshgrid(np.arange(1.0, 54.5, 1.5), np.arange(1.0, 54.5, 1.5)), -1).reshape(-1, 2)
    env = multi(n=600)
    starts = grid[env.scenario.is_free(grid)][:600]
    _, infos = env.reset(seed=0, options={"starts": starts})
    goals = np.array([infos[a]["goal"] for a in env.possible_agents])
    assert env.scenario.is_free(goals).all()
    assert cKDTree(goals).query(goals, k=2)[0][:, 1].min() >= env.min_separation


def test_separated_sampling_draws_as_the_pairwise_reference():
    """The k-d tree sampler redraws exactly what the all-pairs rule redraws."""

    def reference(sc, n, sep, rng):
        pts = sc.sample_states(n, rng)
        for _ in range(1000):
            diff = pts[:, None] - pts[None]
            redraw = np.flatnonzero(np.triu((diff * diff).sum(-1) < sep * sep, k=1).any(axis=0))
            if len(redraw) == 0:
                return pts
            pts[redraw] = sc.sample_states(len(redraw), rng)
        raise AssertionError("reference failed")

    sc = NavigationScenario("CentralObstacle")
    for n, sep, seed in [(5, 2.0, 0), (60, 2.0, 1), (200, 2.0, 2), (120, 3.5, 3)]:
        got = sc.sample_separated(n, sep, np.random.default_rng(seed))
        assert np.array_equal(got, reference(sc, n, sep, np.random.default_rng(seed)))


# --------------------------------------------------------------------- observations_at
def test_observations_at_matches_the_observations_of_both_envs():
    env, par = single(), multi(n=2)
    pts = np.array([(5.0, 10.0), (50.0, 45.0)])
    obs, _ = env.reset(options={"start": pts[0], "goal": pts[1]})
    pobs, _ = par.reset(options={"starts": pts, "goals": pts[::-1]})
    for e in (env, par):
        got = e.observations_at(pts)
        assert got.dtype == np.float32 and got.shape == (2, 2)
        assert np.array_equal(got[0], obs["observation"]) and np.array_equal(got[1], obs["desired_goal"])
        assert np.array_equal(got[1], pobs["agent_1"]["observation"])
        assert e.observations_at(pts[None]).shape == (1, 2, 2) and e.observations_at(pts[0]).shape == (2,)
    with pytest.raises(ValueError, match="states"):
        env.observations_at([1.0, 2.0, 3.0])


def test_observations_at_renders_panoramas_in_one_batch():
    env = single("SafeApartment0-v0")
    obs, info = env.reset(seed=1)
    pts = np.stack([info["position"], info["goal"]])
    got = env.observations_at(pts)
    assert got.dtype == np.uint8 and got.shape == (2, 4, 32, 32, 4)
    assert np.array_equal(got[0], obs["observation"]) and np.array_equal(got[1], obs["desired_goal"])
    assert env.observations_at(pts[0]).shape == (4, 32, 32, 4)
    assert env.observations_at(np.zeros((0, 2))).shape == (0, 4, 32, 32, 4)
    par = multi(n=2, env_id="SafeApartment0-v0")
    pobs, _ = par.reset(seed=1)
    goals = par.goals
    assert np.array_equal(par.observations_at(goals)[1], pobs["agent_1"]["desired_goal"])


# --------------------------------------------------------------------- stable-baselines3
def test_sb3_check_env_passes_on_the_unwrapped_vector_env():
    """SB3 calls compute_reward on the env it gets; Gymnasium's wrappers do not forward it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(gym.make("SafeCentralObstacle-v0").unwrapped, warn=True)
