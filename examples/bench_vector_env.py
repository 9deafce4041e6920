"""Steps per second of the native vector env against Gymnasium's SyncVectorEnv, in one run.

    python examples/bench_vector_env.py                     # SafeCentralObstacle-v0, N = 64
    python examples/bench_vector_env.py --num-envs 8 64 256 --steps 200

Both are made by ``gymnasium.make_vec(id, num_envs=N, vectorization_mode=...)`` ("sync" and
"vector_entry_point") and step the same random actions (seeded) from ``reset(seed=0)`` for
``--steps`` vector steps, autoresets included (20-step episodes). Prints sub-env steps per second
and the ratio native / sync. The two produce the same observations, rewards and costs (a test
checks it), so the ratio is the price of stepping N envs one by one.
"""
from __future__ import annotations

import argparse
import time
from typing import Sequence

import gymnasium as gym
import numpy as np

import safe_mapf_envs  # noqa: F401  (registers the ids)


def steps_per_second(env_id: str, num_envs: int, mode: str, steps: int) -> float:
    """Sub-env steps per second of ``steps`` vector steps with seeded random actions."""
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(steps, num_envs, 2)).astype(np.float32)
    env.reset(seed=0)
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    elapsed = time.perf_counter() - t0
    env.close()
    return steps * num_envs / elapsed


def main(argv: Sequence[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--env", default="SafeCentralObstacle-v0", help="a registered id with vector observations")
    p.add_argument("--num-envs", type=int, nargs="+", default=[64], help="sub-env counts N")
    p.add_argument("--steps", type=int, default=300, help="vector steps timed per row")
    args = p.parse_args(argv)
    if args.steps < 1 or min(args.num_envs) < 1:
        p.error("--steps and --num-envs must be positive")
    for n in args.num_envs:
        sync = steps_per_second(args.env, n, "sync", args.steps)
        native = steps_per_second(args.env, n, "vector_entry_point", args.steps)
        print(f"{args.env}  N={n:<4} sync {sync:9,.0f} steps/s  native {native:9,.0f} steps/s  "
              f"ratio {native / sync:5.1f}x", flush=True)


if __name__ == "__main__":
    main()
