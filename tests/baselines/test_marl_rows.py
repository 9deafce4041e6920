"""``--methods ippo mappo_lag``: the MARL policies as rows of the evaluation, in both protocols."""
import json

import numpy as np
import pytest
import torch

import safe_mapf_envs
from agents.marl import MarlConfig, train_marl
from agents.marl.loading import MarlAgent
from baselines.cli import main
from baselines.marl_rows import execute_marl

ENV = "SafeCenterDot-v0"


@pytest.fixture(scope="module")
def policies(tmp_path_factory):
    """A tiny policy of each trainer (a few hundred steps: the rows, not the skill, are under test)."""
    torch.set_num_threads(1)
    base = tmp_path_factory.mktemp("marl")
    out = {}
    for algo in ("ippo", "mappo-lag"):
        cfg = MarlConfig(algo=algo, env_id=ENV, n_agents=2, timesteps=256, n_envs=2, n_steps=16, batch_size=32,
                         n_epochs=1, max_cycles=10, eval_freq=0, eval_episodes=1, net_arch=[16], progress_bar=False,
                         out_dir=str(base / algo))
        out[algo] = train_marl(cfg)["model"]
    return out


def _agent(act):
    return MarlAgent(act, {"algo": "stand-in", "env_id": ENV, "obs_dim": 4})


def test_execute_marl_counts_cost_arrivals_and_failures():
    env = safe_mapf_envs.parallel_env(ENV, n_agents=2, max_cycles=40)
    starts, goals = np.array([[2.0, 2.0], [13.0, 2.0]]), np.array([[2.0, 8.0], [13.0, 8.0]])
    # straight to the goal at full speed: both arrive along the walls, far from the block
    toward = _agent(lambda o: np.clip((o[:, 2:4] - o[:, :2]) * 15.0, -1, 1))
    ex = execute_marl(env, toward, starts, goals, seed=0)
    assert ex.success and ex.reached.all() and not ex.failures and ex.plan_status == "direct"
    assert 5 <= ex.steps <= 7 and ex.trajectories.shape == (ex.steps + 1, 2, 2)
    # standing still: nobody arrives, each failure has a reason, cost is counted every step
    still = _agent(lambda o: np.zeros((len(o), 2)))
    ex = execute_marl(env, still, starts, goals, seed=0)
    assert not ex.success and ex.steps == 40 and [f.agent for f in ex.failures] == ["agent_0", "agent_1"]
    step_cost = env.scenario.field.cost(starts)
    assert np.allclose(ex.cost, 40 * step_cost)
    lone = safe_mapf_envs.parallel_env(ENV, n_agents=1, max_cycles=3, agent_collisions=False)
    near = np.array([[5.0, 7.5]])  # within the block's cost radius: the start's cost counts once more
    paper = execute_marl(lone, still, near, np.array([[2.0, 2.0]]), count_start_cost=True)
    assert np.isclose(paper.cost[0], 4 * lone.scenario.field.cost(near)[0]) and paper.cost[0] > 0


@pytest.mark.parametrize("protocol", ["strict", "paper"])
def test_evaluate_command_adds_the_marl_rows(policies, protocol, tmp_path, capsys):
    argv = ["evaluate", "--env", ENV, "--agents", "1", "2", "--problems", "1", "--difficulty", "easy",
            "--methods", "ippo", "mappo_lag", "--ippo", policies["ippo"], "--mappo-lag", policies["mappo-lag"],
            "--nodes", "150", "--json", "--out", str(tmp_path), "--protocol", protocol]
    if protocol == "strict":
        argv.append("--no-figure")
    else:
        argv += ["--paper-candidates", "50"]
    assert main(argv) == 0
    agg = json.loads(capsys.readouterr().out)
    assert {(a["method"], a["agents"]) for a in agg} == {(m, k) for m in ("ippo", "mappo_lag") for k in (1, 2)}
    assert all(a["runs"] == 1 for a in agg)
    table = (tmp_path / "table.md").read_text()
    assert "IPPO (MARL)" in table and "MAPPO-Lagrangian (MARL)" in table


def test_evaluate_names_a_missing_marl_policy_before_any_work(tmp_path, capsys):
    assert main(["evaluate", "--env", "SafeFourRooms-v0", "--methods", "ippo", "--out", str(tmp_path)]) == 2
    assert "no shipped ippo policy for 'SafeFourRooms-v0'" in capsys.readouterr().err
    assert main(["evaluate", "--env", ENV, "--methods", "mappo_lag", "--mappo-lag", str(tmp_path / "x.pt"),
                 "--out", str(tmp_path)]) == 2
    assert "no MARL checkpoint" in capsys.readouterr().err
