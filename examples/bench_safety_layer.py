"""The safety layer against the world's physics, without learned agents.

Every agent drives at its goal with noise added to its action (so that agents press into walls,
slide along them, meet box corners and crowd each other), and the layer filters every joint action
before the env steps. The script counts the contacts between agents that begin, with the layer and
without it, over the same episodes; the layer reads only the team's positions and the map's walls.

    python examples/bench_safety_layer.py
    python examples/bench_safety_layer.py --envs SafeApartment3-v0 --agents 30 --episodes 6 --noise 0.7
"""
from __future__ import annotations

import argparse
import time
from typing import Dict, Tuple

import numpy as np

import safe_mapf_envs
from agents.search import SafetyLayer, team_positions

APARTMENTS = [f"SafeApartment{k}-v0" for k in range(4)]


def drive(env_id: str, n_agents: int, seed: int, steps: int, noise: float, layer_on: bool) -> Tuple[int, int, int]:
    """One episode: ``(contacts begun, agents that touched another, agents arrived)``."""
    env = safe_mapf_envs.parallel_env(env_id, n_agents=n_agents, obs_type="vector", max_cycles=steps)
    layer = SafetyLayer.for_env(env)
    env.reset(seed=seed)
    goals = dict(zip(env.possible_agents, np.asarray(env.unwrapped.goals, dtype=np.float64)))
    rng = np.random.default_rng(seed)
    touching: set = set()
    touched: set = set()
    begun = arrived = 0
    while env.agents:
        at = team_positions(env)
        actions: Dict[str, np.ndarray] = {}
        for a in env.agents:
            way = goals[a] - at[a]
            ask = way / max(float(np.hypot(*way)), 1e-9) + rng.normal(0.0, noise, 2)
            actions[a] = np.clip(ask, -1.0, 1.0).astype(np.float32)
        if layer_on:
            actions = layer.filter_agents(actions, at)
        _, _, terminations, _, infos = env.step(actions)
        now = {tuple(sorted((a, b))) for a, info in infos.items() for b in info["collided_with"]}
        begun += len(now - touching)
        touched.update(a for pair in now for a in pair)
        touching = now
        arrived += sum(bool(infos[a]["is_success"]) for a, done in terminations.items() if done)
    env.close()
    return begun, len(touched), arrived


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=APARTMENTS)
    parser.add_argument("--agents", type=int, default=30)
    parser.add_argument("--episodes", type=int, default=6, help="seeds 0, 1, ...")
    parser.add_argument("--steps", type=int, default=300, help="steps per episode")
    parser.add_argument("--noise", type=float, default=0.7, help="std of the noise added to each action component")
    args = parser.parse_args()
    print("| env | agents | episodes | layer | contacts begun | safety rate | arrived | seconds |")
    print("|---|---|---|---|---|---|---|---|")
    for env_id in args.envs:
        for layer_on in (True, False):
            t0 = time.perf_counter()
            runs = [drive(env_id, args.agents, seed, args.steps, args.noise, layer_on) for seed in range(args.episodes)]
            begun, touched, arrived = (sum(r[k] for r in runs) for k in range(3))
            total = args.agents * args.episodes
            print(f"| {env_id} | {args.agents} | {args.episodes} | {'on' if layer_on else 'off'} | {begun} | "
                  f"{1 - touched / total:.1%} | {arrived / total:.1%} | {time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
