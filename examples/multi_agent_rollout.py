"""N agents on one map with the PettingZoo parallel API.

Every agent runs the same single-agent controller on its own observation: head straight for
the goal, and wait while the nearest other agent (the ``neighbors`` key) is close and in the
way, unless it is the agent with the lower index of the two. The script prints each
agent's outcome, cost and contacts, and writes a top-down picture of the episode.

    python examples/multi_agent_rollout.py --n-agents 8 --seed 3
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, fields
from pathlib import Path

import cv2
import numpy as np

import safe_mapf_envs
from baselines.figures import caption


@dataclass
class Settings:
    """What to run."""

    env_id: str = "SafeCentralObstacle-v0"
    """registered single-agent id whose map the agents share"""
    n_agents: int = 6
    """number of agents"""
    seed: int = 0
    """seed of the sampled starts and goals"""
    max_cycles: int = 300
    """steps before every agent is truncated"""
    yield_distance: float = 2.0
    """an agent waits while a higher-priority agent this close (world units) is ahead of it"""
    out: Path = Path("demo_out/multi_rollout.png")
    """where to write the picture"""


def controller(obs: dict, index: int, env, yield_distance: float) -> np.ndarray:
    """Greedy goal seeking with a yield rule, from the agent's observation alone."""
    heading = env.denormalize(obs["desired_goal"] - obs["observation"])
    nearest = env.denormalize(obs["neighbors"][0])
    dist = float(np.linalg.norm(nearest))
    ahead = float(nearest @ heading) > 0
    if index > 0 and dist < yield_distance and ahead:
        return np.zeros(2, np.float32)
    return np.clip(heading, -1.0, 1.0).astype(np.float32)


def main(cfg: Settings) -> None:
    env = safe_mapf_envs.parallel_env(
        cfg.env_id, n_agents=cfg.n_agents, max_cycles=cfg.max_cycles, observe_neighbors=1, render_mode="rgb_array"
    )
    obs, infos = env.reset(seed=cfg.seed)
    index = env.agent_name_mapping
    cost = dict.fromkeys(env.possible_agents, 0.0)
    contacts = dict.fromkeys(env.possible_agents, 0)
    arrived_at = {}
    t = 0
    while env.agents:
        actions = {a: controller(obs[a], index[a], env, cfg.yield_distance) for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
        t += 1
        for a, info in infos.items():
            cost[a] += info["cost"]
            contacts[a] += info["collisions"]
            if terminations[a]:
                arrived_at[a] = t
    for a in env.possible_agents:
        outcome = f"arrived after {arrived_at[a]:3d} steps" if a in arrived_at else "did not arrive        "
        print(f"{a:>9}: {outcome}  cumulative cost {cost[a]:7.2f}  contacts {contacts[a]}")
    print(f"{len(arrived_at)}/{cfg.n_agents} agents arrived; total cost {sum(cost.values()):.2f}")
    cfg.out.parent.mkdir(parents=True, exist_ok=True)
    picture = caption(env.render(), [
        f"{cfg.env_id}, {cfg.n_agents} agents, seed {cfg.seed}: {len(arrived_at)}/{cfg.n_agents} arrived",
        "discs: agents (thick ring: arrived), x: goals, lines: trails, black crosses: contacts; red: cost",
    ])
    cv2.imwrite(str(cfg.out), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    print(f"wrote {cfg.out}")
    env.close()


def parse_args() -> Settings:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    defaults = Settings()
    for f in fields(Settings):
        default = getattr(defaults, f.name)
        parser.add_argument(f"--{f.name.replace('_', '-')}", type=type(default), default=default)
    return Settings(**vars(parser.parse_args()))


if __name__ == "__main__":
    main(parse_args())
