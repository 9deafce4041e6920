"""Models refuse inputs that would give meaningless actions or plans, before any work."""
import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import SAC

import safe_mapf_envs  # noqa: F401
from agents import load_pretrained
from agents.search import SearchPolicy


@pytest.fixture(scope="module")
def centerdot():
    return load_pretrained("SafeCenterDot-v0", kind="unconstrained")


def test_predict_refuses_nan_and_inf_observations(centerdot):
    obs, _ = gym.make("SafeCenterDot-v0").reset(seed=0)
    action, _ = centerdot.predict(obs, deterministic=True)
    assert np.isfinite(action).all()
    for key, bad in (("observation", np.nan), ("desired_goal", np.inf)):
        broken = {**obs, key: np.array([bad, 0.5], np.float32)}
        with pytest.raises(ValueError, match=f"{key} contains NaN or inf"):
            centerdot.predict(broken)
    batch = {k: np.stack([v, v]) for k, v in obs.items()}
    batch["observation"][1, 0] = np.nan
    with pytest.raises(ValueError, match="observation contains NaN"):
        centerdot.predict(batch)


def test_a_panorama_model_refuses_float_images():
    model = load_pretrained("SafeApartment0-v0", kind="unconstrained")
    obs, _ = gym.make("SafeApartment0-v0").reset(seed=0)
    assert model.predict(obs, deterministic=True)[0].shape == (2,)
    floats = {k: v.astype(np.float32) / 255.0 for k, v in obs.items()}
    with pytest.raises(ValueError, match="uint8 images"):
        model.predict(floats)
    with pytest.raises(ValueError, match="obs must be uint8 images"):
        model.distance(floats["observation"], obs["desired_goal"])
    # integer images in range are taken as they are
    as_int = {k: v.astype(np.int64) for k, v in obs.items()}
    assert np.allclose(model.predict(as_int, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


def test_search_policy_refuses_models_of_two_envs_and_a_critic_without_pairwise(centerdot):
    other = load_pretrained("SafeCentralObstacle-v0", kind="constrained")
    with pytest.raises(ValueError, match="trained on SafeCenterDot-v0 and the driver on SafeCentralObstacle-v0"):
        SearchPolicy.from_models(centerdot, other, n_nodes=20)
    torch.set_num_threads(1)
    sac = SAC("MultiInputPolicy", gym.make("SafeCenterDot-v0"), device="cpu")
    with pytest.raises(ValueError, match="a SAC has no pairwise"):
        SearchPolicy.from_models(sac, n_nodes=20)
    with pytest.raises(ValueError, match="observe different spaces"):
        SearchPolicy.from_models(centerdot, SAC("MlpPolicy", "Pendulum-v1", device="cpu"), n_nodes=20)
    # an SB3 model of the same env can drive, the critic judging the waypoints
    policy = SearchPolicy.from_models(centerdot, sac, n_nodes=20, distance_model=centerdot)
    assert policy.policy_model is sac and policy.distance_model is centerdot
