"""Measure the panorama raycaster and the visual environments: panoramas per second (batched
and single) and environment steps per second, in one process.

Run: ``python examples/bench_panorama.py [--batch 20] [--seconds 1.0] [--json]``

Each figure is the best of ``--repeats`` timed runs of about ``--seconds`` each. Rates are
given in wall-clock time and, in brackets, in this process's CPU time: on a shared machine the
wall-clock rate drops with the load, the CPU-time rate shows what one free core does.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Callable, Dict, List, Tuple

import gymnasium as gym
import numpy as np

import safe_mapf_envs
from safe_mapf_envs.scenario import NavigationScenario
from safe_mapf_envs.sensors import PanoramaSensor, scene_for_layout

VISUAL_IDS = [s.id for s in safe_mapf_envs.ENV_SPECS if s.obs_type == "panorama"]


def best_rate(fn: Callable[[], int], seconds: float, repeats: int) -> Tuple[float, float]:
    """Items per second of ``fn`` (which returns how many it produced): best wall-clock and best CPU-time rate."""
    fn()  # warm up
    wall = cpu = 0.0
    for _ in range(repeats):
        n, t0, c0 = 0, time.perf_counter(), time.process_time()
        while True:
            n += fn()
            dt = time.perf_counter() - t0
            if dt >= seconds:
                break
        wall = max(wall, n / dt)
        cpu = max(cpu, n / max(time.process_time() - c0, 1e-9))
    return wall, cpu


def bench_renderer(env_id: str, batch: int, seconds: float, repeats: int) -> Dict[str, Tuple[float, float]]:
    spec = safe_mapf_envs.env_spec(env_id)
    layout = safe_mapf_envs.get_map(spec.layout)
    radius = spec.kwargs.get("agent_radius", 0.5)
    sensor = PanoramaSensor(scene_for_layout(layout))
    pts = NavigationScenario(layout, agent_radius=radius).sample_states(1000, np.random.default_rng(0))
    state = {"i": 0}

    def batched() -> int:
        i = state["i"] = (state["i"] + batch) % (len(pts) - batch)
        sensor.render(pts[i:i + batch])
        return batch

    def single() -> int:
        i = state["i"] = (state["i"] + 1) % len(pts)
        sensor.render(pts[i])
        return 1

    def with_agents() -> int:  # every agent's view with the other agents drawn in it
        i = state["i"] = (state["i"] + batch) % (len(pts) - batch)
        p = pts[i:i + batch]
        sensor.render(p, agents=p, agent_radius=radius, self_index=np.arange(batch))
        return batch

    return {
        "batched_per_s": best_rate(batched, seconds, repeats),
        "single_per_s": best_rate(single, seconds, repeats),
        "batched_with_agents_per_s": best_rate(with_agents, seconds, repeats),
    }


def bench_env(env_id: str, seconds: float, repeats: int) -> Tuple[float, float]:
    """Random-action steps per second through ``gymnasium.make`` (time limit 20, resets included)."""
    env = gym.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def run() -> int:
        for a in rng.uniform(-1, 1, size=(50, 2)).astype(np.float32):
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return 50

    return best_rate(run, seconds, repeats)


def bench_parallel(env_id: str, n_agents: int, seconds: float, repeats: int) -> Tuple[float, float]:
    """Agent-steps per second of the PettingZoo parallel env with panorama observations."""
    env = safe_mapf_envs.parallel_env(env_id, n_agents=n_agents, max_cycles=20)
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def run() -> int:
        if not env.agents:
            env.reset()
        acts = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
        env.step(acts)
        return len(acts)

    return best_rate(run, seconds, repeats)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, default=20, help="panoramas per batched call (default 20)")
    p.add_argument("--seconds", type=float, default=1.0, help="length of one timed run (default 1.0)")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per figure, best kept (default 3)")
    p.add_argument("--agents", type=int, default=10, help="agents in the multi-agent benchmark (default 10)")
    p.add_argument("--json", action="store_true", help="print JSON")
    args = p.parse_args()
    if args.batch < 1 or args.seconds <= 0 or args.repeats < 1 or args.agents < 1:
        raise ValueError(f"--batch, --seconds, --repeats and --agents must be positive, got {vars(args)}")
    rows: List[Dict] = []
    if not args.json:
        print(f"per second, wall clock (CPU time); batch {args.batch}, {args.agents} agents in the parallel env")
        print(f"{'id':30s} {'panoramas batched':>20s} {'panoramas single':>20s} {'batched + agents':>20s} "
              f"{'env steps':>18s} {'parallel agent-steps':>20s}", flush=True)
    for i, env_id in enumerate(VISUAL_IDS):
        # each row takes 5 figures x --repeats x --seconds: say what is being timed meanwhile
        print(f"[{i + 1}/{len(VISUAL_IDS)}] timing {env_id} (about {5 * args.repeats * args.seconds:.0f} s) ...",
              file=sys.stderr, flush=True)
        row = {"env_id": env_id, **bench_renderer(env_id, args.batch, args.seconds, args.repeats)}
        row["env_steps_per_s"] = bench_env(env_id, args.seconds, args.repeats)
        row["parallel_agent_steps_per_s"] = bench_parallel(env_id, args.agents, args.seconds, args.repeats)
        rows.append(row)
        if not args.json:
            cells = [f"{w:,.0f} ({c:,.0f})" for w, c in list(row.values())[1:]]
            print(f"{env_id:30s} " + " ".join(f"{c:>20s}" if i != 3 else f"{c:>18s}" for i, c in enumerate(cells)),
                  flush=True)
    if args.json:
        out = [{k: (v if k == "env_id" else {"wall": v[0], "cpu": v[1]}) for k, v in r.items()} for r in rows]
        print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
