"""The main job (``make demo``).

Runs a scripted rollout on ``SafeCentralObstacle-v0``: a greedy controller heads straight for
the goal, which takes it close past the central block. It prints the episode's cost and writes a
top-down picture of the trajectory to ``demo_out/rollout.png``.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

import safe_mapf_envs  # noqa: F401  (registers the ids)


def main(out_dir: Path = Path("demo_out")) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    env = gym.make("SafeCentralObstacle-v0", render_mode="rgb_array", max_episode_steps=100)
    obs, info = env.reset(seed=0, options={"start": (5.0, 40.0), "goal": (50.0, 38.0)})
    total_cost, steps = 0.0, 0
    terminated = truncated = False
    while not (terminated or truncated):
        delta = env.unwrapped.denormalize(obs["desired_goal"] - obs["observation"])
        action = np.clip(delta, -1.0, 1.0).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        total_cost += info["cost"]
        steps += 1
    path = out_dir / "rollout.png"
    cv2.imwrite(str(path), cv2.cvtColor(env.render(), cv2.COLOR_RGB2BGR))
    print(f"greedy rollout: reached goal={terminated} in {steps} steps, cumulative cost {total_cost:.2f}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
