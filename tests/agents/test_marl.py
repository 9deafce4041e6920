"""The multi-agent RL baselines: a few hundred steps of each trainer, save/load, resume, bad input."""
import json

import numpy as np
import pytest
import torch

from agents.marl import MarlConfig, evaluate_policy, load_marl, train_marl
from agents.marl.mappo_lag import _gae

TINY = dict(env_id="SafeCenterDot-v0", n_agents=2, timesteps=320, n_envs=2, n_steps=16, batch_size=32, n_epochs=2,
            max_cycles=12, eval_freq=128, eval_episodes=2, net_arch=[16], progress_bar=False)


@pytest.fixture(autouse=True)
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("algo,suffix", [("ippo", ".zip"), ("mappo-lag", ".pt")])
def test_trainer_runs_saves_and_the_loaded_policy_reproduces_its_evaluation(algo, suffix, tmp_path):
    out = tmp_path / algo
    summary = train_marl(MarlConfig(algo=algo, out_dir=str(out), **TINY), command=["safe-mapf", "train-marl"])
    assert summary["timesteps"] >= 320 and summary["model"].endswith("model" + suffix)
    lines = [json.loads(x) for x in (out / "evaluations.jsonl").read_text().splitlines()]
    assert len(lines) >= 3 and lines[-1]["timesteps"] == summary["timesteps"]  # periodic + final
    meta = json.loads((out / "model.json").read_text())
    assert meta["algo"] == algo and meta["command"] == ["safe-mapf", "train-marl"] and meta["obs_dim"] == 4
    agent = load_marl(summary["model"], env_id="SafeCenterDot-v0")
    obs = np.random.default_rng(0).random((7, 4), dtype=np.float32)
    a = agent.act(obs)
    assert a.shape == (7, 2) and np.all(np.abs(a) <= 1.0) and np.array_equal(a, agent.act(obs))
    # the loaded policy is the trained one: the same held-out episodes give the same figures
    again = evaluate_policy(agent.act, "SafeCenterDot-v0", 2, 12, 2, 2024)
    assert again == summary["final_evaluation"]
    if algo == "mappo-lag":
        assert summary["lagrange_multiplier"] >= 0.0
    with pytest.raises(ValueError, match="trained on 'SafeCenterDot-v0'"):
        load_marl(summary["model"], env_id="SafeCentralObstacle-v0")
    with pytest.raises(ValueError, match=r"shape \(n, 4\)"):
        agent.act(np.zeros((3, 5)))


@pytest.mark.parametrize("algo", ["ippo", "mappo-lag"])
def test_resume_continues_from_the_last_resume_point(algo, tmp_path):
    out = str(tmp_path / "run")
    cfg = dict(TINY, algo=algo, out_dir=out, timesteps=200)
    first = train_marl(MarlConfig(**cfg))
    with pytest.raises(ValueError, match="is not empty"):
        train_marl(MarlConfig(**cfg))
    second = train_marl(MarlConfig(**dict(cfg, timesteps=400, resume=True)))
    assert second["timesteps"] >= 400 > first["timesteps"]
    steps = [json.loads(x)["timesteps"] for x in (tmp_path / "run" / "evaluations.jsonl").read_text().splitlines()]
    assert steps == sorted(steps) and steps[-1] == second["timesteps"]
    with pytest.raises(ValueError, match="holds a"):  # another algorithm's run
        train_marl(MarlConfig(**dict(cfg, algo="mappo-lag" if algo == "ippo" else "ippo", resume=True)))


def test_resume_needs_a_resume_point(tmp_path):
    with pytest.raises(ValueError, match="nothing to resume"):
        train_marl(MarlConfig(**dict(TINY, out_dir=str(tmp_path / "empty"), resume=True)))


@pytest.mark.parametrize("kwargs,message", [
    ({"algo": "qmix"}, "algo must be one of"),
    ({"env_id": "SafeApartment0-v0"}, "panorama"),
    ({"env_id": "SafeNope-v0"}, "unknown env id"),
    ({"n_agents": 0}, "n_agents must be an integer >= 1"),
    ({"gamma": 1.5}, "gamma must be a number > 0 and <= 1"),
    ({"cost_limit": -1.0}, "cost_limit must be a number >= 0"),
    ({"net_arch": []}, "net_arch"),
])
def test_bad_settings_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        MarlConfig(**kwargs)


def test_gae_stops_at_the_end_of_an_agent_episode():
    # one env copy, one agent: rewards -1, -1 | 0 (arrived at t=2, done), then a new episode
    rew = np.array([-1.0, -1.0, 0.0, -1.0]).reshape(4, 1, 1)
    val = np.array([-2.0, -1.5, -0.5, -3.0]).reshape(4, 1, 1)
    done = np.array([0.0, 0.0, 1.0, 0.0]).reshape(4, 1, 1)
    last = np.array([[-2.5]])
    adv, ret = _gae(rew, val, last, done, gamma=1.0, lam=1.0)
    # with gamma = lambda = 1 the return is the sum of rewards to the episode's end (plus the bootstrap)
    assert np.allclose(ret.ravel(), [-2.0, -1.0, 0.0, -3.5])
    assert np.allclose(adv, ret - val)


def test_the_multiplier_waits_for_lagrange_start_then_moves_with_the_cost(tmp_path):
    cfg = dict(TINY, algo="mappo-lag", eval_freq=0, lagrange_lr=1.0, lagrange_init=0.5, cost_limit=0.0)
    held = train_marl(MarlConfig(**dict(cfg, out_dir=str(tmp_path / "a"), lagrange_start=10**6)))
    assert held["lagrange_multiplier"] == 0.5
    # a cost limit of 0: any cost above it raises the multiplier
    moved = train_marl(MarlConfig(**dict(cfg, out_dir=str(tmp_path / "b"))))
    assert moved["lagrange_multiplier"] > 0.5


def test_potential_shaping_adds_the_distance_covered():
    from agents.marl.common import make_env

    raw = make_env("SafeCenterDot-v0", 1, 20)
    shaped = make_env("SafeCenterDot-v0", 1, 20, shaping=1.0, gamma=1.0)
    options = {"starts": [(2.0, 2.0)], "goals": [(2.0, 7.5)]}
    totals = []
    for env in (raw, shaped):
        env.reset(seed=0, options=options)
        total = 0.0
        while env.agents:
            _, r, _, _, _ = env.step({"agent_0": np.array([0.0, 1.0])})
            total += r["agent_0"]
        totals.append(total)
    # with gamma = 1 the shaping telescopes to phi(goal) - phi(start) = the start's distance, 5.5 steps
    assert totals[0] < 0 and np.isclose(totals[1] - totals[0], 5.5)
    assert shaped.state().shape == (4,) and shaped.agent_name_mapping == {"agent_0": 0}


def test_resume_refuses_other_settings_and_overwrite_starts_anew(tmp_path):
    out = tmp_path / "run"
    cfg = dict(TINY, algo="mappo-lag", out_dir=str(out), timesteps=160)
    train_marl(MarlConfig(**cfg))
    with pytest.raises(ValueError, match='--agents: 2 there, 3 now'):
        train_marl(MarlConfig(**dict(cfg, n_agents=3, resume=True)))
    (out / "notes.txt").write_text("mine")
    again = train_marl(MarlConfig(**dict(cfg, seed=5, overwrite=True)))
    assert again["timesteps"] >= 160
    assert json.loads((out / "config.json").read_text())["config"]["seed"] == 5 and "resumed" not in json.loads(
        (out / "config.json").read_text())
    assert (out / "notes.txt").read_text() == "mine"
