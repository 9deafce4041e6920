"""``safe-mapf bench-env``: environment steps per second."""
from __future__ import annotations

import argparse
import json
import time


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench-env", help="measure environment steps per second", description=run.__doc__)
    p.add_argument("env_id", metavar="ID", help="a registered id, e.g. SafeCentralObstacle-v0")
    p.add_argument("--steps", type=int, default=20000,
                   help="environment steps to time, for each agent count (default 20000); episodes are reset "
                        "as they end, and the resets are timed too")
    p.add_argument("--agents", type=int, nargs="*", default=None,
                   help="time the PettingZoo parallel env with these agent counts instead")
    p.add_argument("--seed", type=int, default=0, help="seed of the resets and the random actions")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def bench_single(env_id: str, steps: int, seed: int = 0) -> dict:
    """Time ``steps`` random-action steps through ``gymnasium.make`` with its default wrappers.

    Episodes are reset as they end; the resets are inside the timed loop. Returns the
    counts and rates in a dict (``steps``, ``agent_steps``, ``resets``, ``seconds``, ...).
    """
    import gymnasium as gym
    import numpy as np

    import safe_mapf_envs  # noqa: F401

    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = np.random.default_rng(seed).uniform(-1, 1, size=(steps, 2)).astype(np.float32)
    resets = 0
    t0 = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
            resets += 1
    dt = time.perf_counter() - t0
    env.close()
    return {"env_id": env_id, "agents": 1, "steps": steps, "agent_steps": steps, "resets": resets,
            "seconds": dt, "steps_per_s": steps / dt, "agent_steps_per_s": steps / dt}


def bench_parallel(env_id: str, n_agents: int, steps: int, seed: int = 0) -> dict:
    """Time ``steps`` steps of the PettingZoo parallel env with ``n_agents`` agents taking random actions.

    An episode ends when every agent is done; the env is then reset inside the timed loop.
    ``agent_steps`` counts the actions of the agents still live at each step.
    """
    import numpy as np

    import safe_mapf_envs

    env = safe_mapf_envs.parallel_env(env_id, n_agents=n_agents)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    agent_steps = 0
    resets = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        if not env.agents:
            env.reset()
            resets += 1
        acts = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
        agent_steps += len(acts)
        env.step(acts)
    dt = time.perf_counter() - t0
    env.close()
    return {"env_id": env_id, "agents": n_agents, "steps": steps, "agent_steps": agent_steps, "resets": resets,
            "seconds": dt, "steps_per_s": steps / dt, "agent_steps_per_s": agent_steps / dt}


def run(args: argparse.Namespace) -> int:
    """Time random-action steps of an environment and print steps (or agent-steps) per second.

    Every row times exactly ``--steps`` environment steps (for each agent count of
    ``--agents``), resetting episodes as they end; the resets are part of the timing.
    """
    import safe_mapf_envs
    from safe_mapf_envs.registration import check_env_id

    check_env_id(args.env_id)
    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if args.agents:
        bad = [n for n in args.agents if n < 1]
        if bad:
            raise ValueError(f"--agents must be counts >= 1, got {bad}")
        for n in args.agents:  # an id of this package and room for n agents, before timing anything
            safe_mapf_envs.parallel_env(args.env_id, n_agents=n).close()
        rows = [bench_parallel(args.env_id, n, args.steps, args.seed) for n in args.agents]
    else:
        rows = [bench_single(args.env_id, args.steps, args.seed)]
    if args.json:
        print(json.dumps(rows if len(rows) > 1 else rows[0], indent=2))
    else:
        for r in rows:
            print(f"{r['env_id']}  agents={r['agents']}  timed {r['steps']} steps ({r['agent_steps']} agent-steps, "
                  f"{r['resets']} resets included) in {r['seconds']:.2f} s: "
                  f"{r['steps_per_s']:,.0f} steps/s, {r['agent_steps_per_s']:,.0f} agent-steps/s")
    return 0
