"""The shipped MARL policies: small, loadable, described by the command that trained them."""
import json
import os
from pathlib import Path

import numpy as np
import pytest

import safe_mapf_envs
from agents.marl import load_marl_pretrained, pretrained_marl_path

SHIPPED = [(env, algo) for env in ("SafeCenterDot-v0", "SafeCentralObstacle-v0") for algo in ("ippo", "mappo-lag")]


@pytest.mark.parametrize("env_id,algo", SHIPPED)
def test_shipped_policy_loads_and_records_its_training_command(env_id, algo):
    path = pretrained_marl_path(env_id, algo)
    assert os.path.getsize(path) < 10_000_000
    meta = json.loads(Path(path).with_suffix(".json").read_text())
    assert meta["algo"] == algo and meta["env_id"] == env_id and meta["n_agents"] == 5
    assert meta["command"][:3] == ["safe-mapf", "train-marl", "--algo"] and meta["wall_s"] < 30 * 60
    agent = load_marl_pretrained(env_id, algo)
    env = safe_mapf_envs.parallel_env(env_id, n_agents=3, max_cycles=5)
    obs, _ = env.reset(seed=0)
    actions = agent.act_dict(obs)
    assert set(actions) == set(env.agents) and all(np.all(np.abs(a) <= 1) for a in actions.values())


def test_a_map_without_shipped_policies_is_named():
    with pytest.raises(ValueError, match="no shipped ippo policy for 'SafeMaze-v0'"):
        pretrained_marl_path("SafeMaze-v0", "ippo")
    with pytest.raises(ValueError, match="algo must be one of"):
        pretrained_marl_path("SafeCenterDot-v0", "qmix")
