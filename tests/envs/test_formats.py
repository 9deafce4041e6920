"""observation_format="flat": one Box per observation, for SuperSuit and SB3's Mlp/Cnn policies."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
import supersuit as ss
import torch
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import parallel_api_test
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.preprocessing import is_image_space, is_image_space_channels_first

import safe_mapf_envs
from safe_mapf_envs import flatten_observation

STEP = np.array([0.7, -0.4], np.float32)


def _rollout(env, steps=3):
    obs, _ = env.reset(seed=3)
    out = [obs]
    for _ in range(steps):
        obs, *_ = env.step(STEP)
        out.append(obs)
    return out


def test_flat_vector_observation_is_observation_then_goal():
    flat = gym.make("SafeCentralObstacle-v0", observation_format="flat")
    assert flat.observation_space == gym.spaces.Box(0.0, 1.0, (4,), np.float32)
    gym_check_env(flat.unwrapped, skip_render_check=True)
    for f, d in zip(_rollout(flat), _rollout(gym.make("SafeCentralObstacle-v0"))):
        assert f.dtype == np.float32 and flat.observation_space.contains(f)
        assert np.array_equal(f, np.concatenate([d["observation"], d["desired_goal"]]))
    # the goal methods still take the Dict's goals; compute_reward is the Dict format's alone
    goal_space = flat.unwrapped.goal_observation_space
    assert goal_space["desired_goal"].shape == (2,)
    assert flat.unwrapped.compute_terminated(f[:2], f[2:], {}) in (True, False)
    assert not hasattr(flat.unwrapped, "compute_reward")
    with pytest.raises(AttributeError, match="observation_format='dict' only"):
        flat.unwrapped.compute_reward(f[:2], f[2:], {})


def test_flat_panorama_is_a_channel_first_image_of_the_views_and_the_goal_views():
    kw = {"sensor_kwargs": {"image_size": 8}}
    flat = gym.make("SafeApartment1-v0", observation_format="flat", **kw)
    space = flat.observation_space
    assert space.shape == (4, 16, 32) and space.dtype == np.uint8
    assert is_image_space(space) and is_image_space_channels_first(space)
    for f, d in zip(_rollout(flat, 2), _rollout(gym.make("SafeApartment1-v0", **kw), 2)):
        assert space.contains(f)
        for half, key in enumerate(("observation", "desired_goal")):
            for v in range(4):  # view v of the half at rows half*8.., columns v*8..
                block = f[:, half * 8:(half + 1) * 8, v * 8:(v + 1) * 8]
                assert np.array_equal(block, d[key][v].transpose(2, 0, 1))


def test_flatten_observation_keeps_batch_dimensions():
    rng = np.random.default_rng(0)
    imgs = {k: rng.integers(0, 256, (5, 4, 6, 6, 4), dtype=np.uint8) for k in ("observation", "desired_goal")}
    batch = flatten_observation(imgs)
    assert batch.shape == (5, 4, 12, 24)
    assert np.array_equal(batch[2], flatten_observation({k: v[2] for k, v in imgs.items()}))
    vec = {"observation": rng.random((3, 2)), "desired_goal": rng.random((3, 2)), "neighbors": rng.random((3, 2, 2))}
    assert flatten_observation(vec).shape == (3, 8) and flatten_observation(vec).dtype == np.float32


def test_flat_multi_agent_env_passes_the_pettingzoo_api_test():
    par = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, observation_format="flat",
                                      observe_neighbors=2)
    space = par.observation_space("agent_0")
    assert space.shape == (8,) and space.low[4] == -1.0 and space.high[0] == 1.0
    parallel_api_test(par, num_cycles=30)
    dict_env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=3, observe_neighbors=2)
    f, _ = par.reset(seed=1)
    d, _ = dict_env.reset(seed=1)
    for a in par.possible_agents:
        assert np.array_equal(f[a], np.concatenate([d[a]["observation"], d[a]["desired_goal"],
                                                    d[a]["neighbors"].ravel()]))


def test_supersuit_wrappers_and_ppo_mlp_policy_on_the_flat_multi_agent_env():
    torch.set_num_threads(1)
    par = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=3, observation_format="flat", max_cycles=10)
    env = ss.flatten_v0(ss.black_death_v3(par))
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 2, num_cpus=0,
                                 base_class="stable_baselines3")
    assert venv.num_envs == 6 and venv.observation_space.shape == (4,)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=48, n_epochs=1, device="cpu")
    model.learn(96)  # through several episode ends: agents that arrive are blacked out
    assert model.num_timesteps >= 96
    obs = venv.reset()
    actions, _ = model.predict(obs, deterministic=True)
    assert actions.shape == (6, 2)
    venv.close()


def test_ppo_cnn_policy_reads_flat_panoramas():
    torch.set_num_threads(1)
    env = gym.make("SafeApartment0-v0", observation_format="flat")
    assert env.observation_space.shape == (4, 64, 128)
    model = PPO("CnnPolicy", env, n_steps=8, batch_size=8, n_epochs=1, device="cpu", seed=0)
    model.learn(8)
    assert type(model.policy.features_extractor).__name__ == "NatureCNN"


def test_bad_observation_format_names_the_value():
    with pytest.raises(ValueError, match="observation_format.*'flattened'"):
        gym.make("SafeCentralObstacle-v0", observation_format="flattened")
    with pytest.raises(ValueError, match="observation_format"):
        safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", observation_format=None)


@pytest.mark.parametrize("env_id", ["SafeCentralObstacle-v0", "SafeApartment0-v0"])
def test_sb3_check_env_passes_on_the_flat_format_wrapped_or_not(env_id):
    """The flat env has no compute_reward, so SB3 checks it as a plain env (no goal-env rules)."""
    for env in (gym.make(env_id, observation_format="flat"), gym.make(env_id, observation_format="flat").unwrapped):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sb3_check_env(env, warn=True)
    # the Dict format is still a goal env to SB3, checked unwrapped (the wrappers do not forward compute_reward)
    goal_env = gym.make(env_id).unwrapped
    assert hasattr(goal_env, "compute_reward")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SB3 advises flattening the panorama Dict's image keys
        sb3_check_env(goal_env, warn=True)
    with pytest.raises(AttributeError, match="compute_reward"):
        sb3_check_env(gym.make(env_id), warn=False)
