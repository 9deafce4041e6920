"""The native vector env: the same episodes as SyncVectorEnv, stepped in one batch."""
import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401
from safe_mapf_envs.vector import SafeNavigationVectorEnv


def _check_same(a, b):
    """Equal observations (dict or flat), and equal step results and infos."""
    if isinstance(a[0], dict):
        assert all(np.array_equal(a[0][k], b[0][k]) for k in a[0])
    else:
        assert np.array_equal(a[0], b[0])
    if len(a) == 5:
        assert np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3])
    for k in ("cost", "position", "goal", "is_success"):
        assert np.allclose(a[-1][k], b[-1][k]), k


@pytest.mark.parametrize("kwargs", [{}, {"action_noise": 0.3, "observation_format": "flat"}])
def test_native_vector_env_gives_the_sync_vector_env_episodes(kwargs):
    n = 6
    native = gym.make_vec("SafeCenterDot-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    assert isinstance(native.unwrapped, SafeNavigationVectorEnv)
    sync = gym.make_vec("SafeCenterDot-v0", num_envs=n, vectorization_mode="sync", **kwargs)
    assert native.observation_space == sync.observation_space and native.action_space == sync.action_space
    a, b = native.reset(seed=7), sync.reset(seed=7)
    _check_same(a, b)
    rng = np.random.default_rng(0)
    ends = np.zeros(2, int)
    for _ in range(70):
        info = a[-1]  # half the sub-envs head for their goal, the others act at random
        actions = rng.uniform(-1.3, 1.3, size=(n, 2))
        actions[::2] = np.clip(info["goal"][::2] - info["position"][::2], -1, 1)
        a, b = native.step(actions.astype(np.float32)), sync.step(actions.astype(np.float32))
        _check_same(a, b)
        ends += [a[2].sum(), a[3].sum()]
    assert ends[0] > 0 and ends[1] > 0  # episodes ended by arriving and by the time limit, and restarted
    native.close()
    sync.close()


def test_reset_options_and_bad_input():
    env = gym.make_vec("SafeCentralObstacle-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, info = env.reset(seed=0, options={"start": (5.0, 5.0), "goal": (6.5, 5.0)})
    assert np.allclose(info["position"], [[5.0, 5.0]] * 3) and obs["desired_goal"].shape == (3, 2)
    _, reward, terminated, truncated, info = env.step(np.array([[1, 0], [0, 1], [0, 0]], np.float32))
    assert terminated.tolist() == [True, False, False] and reward.tolist() == [0.0, -1.0, -1.0]
    assert not truncated.any() and info["cost"].shape == (3,) and info["_cost"].all()
    with pytest.raises(ValueError, match=r"\(3, 2\) array of finite"):
        env.step(np.full((3, 2), np.nan))
    with pytest.raises(ValueError, match=r"\(3, 2\) array"):
        env.step(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="one seed per sub-env"):
        env.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="panoramas"):
        SafeNavigationVectorEnv(2, layout="CentralObstacle", obs_type="panorama")
    with pytest.raises(ValueError, match="does not render"):
        SafeNavigationVectorEnv(2, render_mode="rgb_array")
    with pytest.raises(ValueError, match="num_envs"):
        SafeNavigationVectorEnv(0)
    with pytest.raises(gym.error.Error, match="vector entry point"):
        gym.make_vec("SafeApartment0-v0", num_envs=2, vectorization_mode="vector_entry_point")
