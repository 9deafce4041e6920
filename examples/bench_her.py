"""Stable-Baselines3's SAC with its ``HerReplayBuffer`` on the default episodes of the 2D maps.

    python examples/bench_her.py                          # 2000, 4000, 6000 steps on each map, seed 0
    python examples/bench_her.py --steps 3000 6000 --seeds 0 1 --episodes 200

Nothing of this project's agents is used: the off-the-shelf SAC, ``MultiInputPolicy``,
``HerReplayBuffer`` (``future`` strategy, 4 relabelled goals per transition) and SB3's defaults
otherwise, on ``gymnasium.make(env_id)`` as registered (20 steps per episode, default resets:
goals within reach of the time limit). HER learns from the reward alone: ``0`` where the
(relabelled) goal is reached, ``-1`` elsewhere, as ``compute_reward`` gives it.

For every training budget in ``--steps`` the script prints the success rate (``info["is_success"]``
at the end of the episode) of the deterministic policy on ``--episodes`` default resets of a
separate evaluation env, and the success rate of the random policy on the same episodes for
reference. One thread (``torch.set_num_threads(1)``); the default run takes about three minutes
per map.
"""
from __future__ import annotations

import argparse
import time
from typing import Callable, List, Sequence

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC, HerReplayBuffer

import safe_mapf_envs  # noqa: F401  (registers the ids)

ENV_IDS = ("SafeCenterDot-v0", "SafeCentralObstacle-v0")


def success_rate(env_id: str, act: Callable[[dict, gym.Env], np.ndarray], episodes: int, seed: int) -> float:
    """Fraction of ``episodes`` default resets (seeded ``seed``, ``seed + 1``, ...) that end at the goal."""
    env = gym.make(env_id)
    env.action_space.seed(seed)
    wins = 0
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(act(obs, env))
            done = terminated or truncated
        wins += bool(info["is_success"])
    env.close()
    return wins / episodes


def run(env_id: str, steps: Sequence[int], seed: int, episodes: int) -> List[str]:
    """Train SAC + HER up to each budget in ``steps`` and return one printed row per budget."""
    model = SAC(
        "MultiInputPolicy", gym.make(env_id), replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        learning_starts=200, seed=seed, device="cpu", verbose=0,
    )
    rows, done_steps, t0 = [], 0, time.perf_counter()
    eval_seed = 10_000 + 1000 * seed  # episodes no training reset used

    def policy(obs: dict, env: gym.Env) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    for budget in sorted(steps):
        model.learn(budget - done_steps, reset_num_timesteps=False)
        done_steps = budget
        train_s = time.perf_counter() - t0
        rate = success_rate(env_id, policy, episodes, eval_seed)
        rows.append(f"{env_id:<24} seed {seed}  {budget:>6} steps  SAC+HER success {rate:6.1%}  "
                    f"(trained {train_s:5.0f} s)")
        print(rows[-1], flush=True)
    return rows


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=list(ENV_IDS), help="registered vector ids")
    parser.add_argument("--steps", nargs="+", type=int, default=[2000, 4000, 6000],
                        help="training budgets (environment steps)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], help="training seeds")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per budget")
    args = parser.parse_args(argv)
    if any(s < 1 for s in args.steps) or args.episodes < 1:
        parser.error("--steps and --episodes must be positive")
    torch.set_num_threads(1)
    for env_id in args.envs:
        rate = success_rate(env_id, lambda obs, env: env.action_space.sample(), args.episodes, 10_000)
        print(f"{env_id:<24} random policy success {rate:6.1%}", flush=True)
        for seed in args.seeds:
            run(env_id, args.steps, seed, args.episodes)


if __name__ == "__main__":
    main()
