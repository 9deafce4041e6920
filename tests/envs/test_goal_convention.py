"""The goal convention SB3's HER relies on (rewards, costs) and default goals within reach."""
import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv

import safe_mapf_envs
from safe_mapf_envs import SafeNavigationEnv

RIGHT = np.array([1.0, 0.0], np.float32)


def test_step_reward_is_zero_on_the_goal_reaching_step_only():
    env = gym.make("SafeCentralObstacle-v0")
    env.reset(options={"start": (5.0, 5.0), "goal": (8.5, 5.0)})
    steps = [env.step(RIGHT) for _ in range(3)]
    assert [s[1] for s in steps] == [-1.0, -1.0, 0.0] and [s[2] for s in steps] == [False, False, True]


def test_compute_reward_on_batches_at_and_away_from_the_goal():
    """As HerReplayBuffer calls it: (B, 2) goals and an object array of info dicts."""
    env = gym.make("SafeCenterDot-v0").unwrapped
    rng = np.random.default_rng(0)
    achieved = env.normalize(env.sample_states(64, rng))
    desired = env.normalize(env.sample_states(64, rng))
    desired[::2] = achieved[::2]  # relabelled to the achieved goal itself
    near = env.normalize(env.denormalize(achieved[1::4]) + [0.6, 0.0])  # within goal_threshold (1)
    desired[1::4] = near
    infos = np.array([{"cost": 0.0}] * 64, dtype=object)
    reward = env.compute_reward(achieved, desired, infos)
    assert reward.shape == (64,) and reward.dtype == np.float32
    dist = np.linalg.norm(env.denormalize(achieved) - env.denormalize(desired), axis=1)
    assert np.array_equal(reward, np.where(dist <= env.goal_threshold, 0.0, -1.0))
    assert (reward[::2] == 0).all() and (reward[1::4] == 0).all() and (reward[3::4] == -1).all()
    # one goal, and a (n_envs, batch) leading shape
    assert env.compute_reward(achieved[0], achieved[0], {}) == 0.0
    assert env.compute_reward(achieved[1], desired[3], {}) == -1.0
    assert env.compute_reward(achieved.reshape(4, 16, 2), desired.reshape(4, 16, 2), None).shape == (4, 16)
    term = env.compute_terminated(achieved, desired, infos)
    assert np.array_equal(term, reward == 0) and not env.compute_truncated(achieved, desired, infos).any()


def test_sb3_her_replay_buffer_sees_the_goal_reaching_transitions():
    venv = DummyVecEnv([lambda: gym.make("SafeCenterDot-v0")])
    buf = HerReplayBuffer(400, venv.observation_space, venv.action_space, env=venv, n_sampled_goal=4)
    obs = venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(200):
        action = rng.uniform(-1, 1, size=(1, 2)).astype(np.float32)
        next_obs, reward, done, infos = venv.step(action)
        real_next = {k: v.copy() for k, v in next_obs.items()}
        if done[0]:
            for k in real_next:
                real_next[k][0] = infos[0]["terminal_observation"][k]
        buf.add(obs, real_next, action, reward, done, infos)
        obs = next_obs
    batch = buf.sample(256, env=None)
    reward = batch.rewards.numpy().ravel()
    env = venv.envs[0].unwrapped
    achieved, desired = batch.next_observations["achieved_goal"].numpy(), batch.observations["desired_goal"].numpy()
    dist = np.linalg.norm(env.denormalize(achieved) - env.denormalize(desired), axis=1)
    assert np.array_equal(reward, np.where(dist <= env.goal_threshold, 0.0, -1.0).astype(np.float32))
    assert (reward == 0).sum() >= 20 and (reward == -1).sum() >= 20


def test_compute_cost_is_the_cost_at_the_achieved_position():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    states = env.sample_states(10, np.random.default_rng(1))
    achieved = env.normalize(states)
    cost = env.compute_cost(achieved, achieved[::-1], None)
    assert cost.shape == (10,)
    np.testing.assert_allclose(cost, env.field.cost(states), rtol=1e-5, atol=1e-6)
    assert env.compute_cost(achieved[0], achieved[0], {}) == pytest.approx(float(env.field.cost(states[0])), abs=1e-5)
    # a step's reported cost is the largest over its sub-steps, so at least the end position's
    obs, _ = env.reset(options={"start": (18.0, 27.5), "goal": (1.0, 1.0)})
    obs, _, _, _, info = env.step(np.array([-1.0, 0.0], np.float32))
    assert 0 < env.compute_cost(obs["achieved_goal"], obs["desired_goal"], info) <= info["cost"]
    with pytest.raises(ValueError, match="shape"):
        env.compute_cost(np.zeros(3), np.zeros(3), {})
    with pytest.raises(ValueError, match="panorama"):
        gym.make("SafeApartment0-v0").unwrapped.compute_cost(None, None, {})


def _goal_distances(env, n=40, **reset):
    out = []
    for k in range(n):
        _, info = env.reset(seed=k, **reset)
        out.append(float(env.unwrapped.geodesic_distance(info["position"], info["goal"])))
    return np.array(out)


def test_default_goals_lie_within_reach_of_the_time_limit():
    d20 = _goal_distances(gym.make("SafeCentralObstacle-v0"))
    assert d20.max() <= 20.0 + 1e-6
    # the apartments move 0.25 m per step: 20 steps reach 5 m
    assert _goal_distances(gym.make("SafeApartment0-v0", obs_type="vector"), n=10).max() <= 5.0 + 1e-6
    # "uniform" (constructor or reset option) and the class's own default: anywhere
    uniform = _goal_distances(gym.make("SafeCentralObstacle-v0", goal_distance="uniform"))
    assert uniform.max() > 30.0
    opt = _goal_distances(gym.make("SafeCentralObstacle-v0"), options={"goal_distance": "uniform"})
    assert np.array_equal(opt, uniform)
    assert _goal_distances(SafeNavigationEnv("CentralObstacle")).max() > 30.0
    # a band still overrides
    band = _goal_distances(gym.make("SafeCentralObstacle-v0", goal_distance=(25.0, 30.0)))
    assert band.min() >= 25.0 - 1e-6 and band.max() <= 30.0 + 1e-6
    assert gym.make("SafeCentralObstacle-v0").spec.kwargs["goal_distance"] == (0.0, 20.0)
    assert gym.make("SafeApartment0-v0").spec.kwargs["goal_distance"] == (0.0, 5.0)
    # the multi-agent factories (300-step episodes) keep goals anywhere
    par = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=4)
    assert par.goal_distance is None


def test_bad_goal_distance_names_the_value():
    with pytest.raises(ValueError, match="goal_distance.*'anywhere'"):
        gym.make("SafeCentralObstacle-v0", goal_distance="anywhere")
    env = gym.make("SafeCentralObstacle-v0")
    with pytest.raises(ValueError, match="goal_distance"):
        env.reset(options={"goal_distance": (5.0, 1.0)})


def test_multi_agent_reward_is_zero_for_the_agent_that_arrives():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    env.reset(options={"starts": [(5.0, 5.0), (5.0, 50.0)], "goals": [(6.5, 5.0), (50.0, 50.0)]})
    _, rew, term, _, _ = env.step({"agent_0": RIGHT, "agent_1": RIGHT})
    assert rew == {"agent_0": 0.0, "agent_1": -1.0} and term == {"agent_0": True, "agent_1": False}
