"""SuperSuit's common wrappers on every registered id's multi-agent env (``observation_format="flat"``)."""
import numpy as np
import pytest
import supersuit as ss

import safe_mapf_envs
from safe_mapf_envs.registration import ENV_SPECS

#: small panoramas keep the panorama ids fast
SMALL = {"sensor_kwargs": {"image_size": 8}}


def _parallel(spec, **kwargs):
    extra = SMALL if spec.obs_type == "panorama" else {}
    return safe_mapf_envs.parallel_env(spec.id, n_agents=2, observation_format="flat", **extra, **kwargs)


@pytest.mark.parametrize("spec", ENV_SPECS, ids=[s.id for s in ENV_SPECS])
def test_black_death_flatten_and_vector_env_wrappers(spec):
    par = _parallel(spec, max_cycles=4)
    size = int(np.prod(par.observation_space("agent_0").shape))
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(ss.flatten_v0(ss.black_death_v3(par))), 2,
                                 num_cpus=0, base_class="stable_baselines3")
    assert venv.num_envs == 4 and venv.observation_space.shape == (size,)
    obs = venv.reset()
    assert obs.shape == (4, size) and venv.observation_space.contains(obs[0])
    rng = np.random.default_rng(0)
    ended = np.zeros(4, dtype=bool)
    for _ in range(6):  # past the 4-step episode end: the copies reset themselves
        obs, rewards, dones, infos = venv.step(rng.uniform(-1, 1, (4, 2)).astype(np.float32))
        assert obs.shape == (4, size) and rewards.shape == (4,) and len(infos) == 4
        assert set(np.unique(rewards)) <= {-1.0, 0.0}
        ended |= np.asarray(dones, dtype=bool)  # a copy whose agents arrive early ends before the others
    assert ended.all()
    venv.close()


def test_black_death_keeps_an_arrived_agent_with_zero_observations():
    spec = next(s for s in ENV_SPECS if s.id == "SafeCenterDot-v0")
    env = ss.black_death_v3(_parallel(spec))
    # agent_0 starts half a unit from its goal, agent_1 far from its own
    env.reset(seed=0, options={"starts": [(2.0, 2.0), (12.0, 12.0)], "goals": [(2.5, 2.0), (2.0, 12.0)]})
    _, rew, _, _, _ = env.step({"agent_0": np.zeros(2), "agent_1": np.zeros(2)})
    assert rew == {"agent_0": 0.0, "agent_1": -1.0}  # agent_0 arrived
    assert env.unwrapped.agents == ["agent_1"]
    obs, rew, done, _, _ = env.step({"agent_0": np.ones(2), "agent_1": np.zeros(2)})
    assert env.agents == ["agent_0", "agent_1"] and not any(done.values())  # still there, blacked out
    assert not obs["agent_0"].any() and obs["agent_1"].any() and rew == {"agent_0": 0.0, "agent_1": -1.0}
