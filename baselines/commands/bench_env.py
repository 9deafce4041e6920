"""``safe-mapf bench-env``: environment steps per second, and the memory the process holds."""
from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from typing import Any, Dict, Optional


def register(sub: argparse._SubParsersAction) -> None:
    from baselines.cli import add_map_argument

    p = sub.add_parser("bench-env", help="measure environment steps per second and memory", description=run.__doc__)
    p.add_argument("env_id", metavar="ID", help="a registered id, e.g. SafeCentralObstacle-v0")
    p.add_argument("--steps", type=int, default=20000,
                   help="environment steps to time, for each agent count (default 20000); episodes are reset "
                        "as they end, and the resets are timed too")
    p.add_argument("--agents", type=int, nargs="*", default=None,
                   help="time the PettingZoo parallel env with these agent counts instead")
    p.add_argument("--max-cycles", type=int, default=None, metavar="N",
                   help="episode length of the parallel env (default: its own, 300 steps); needs --agents")
    add_map_argument(p, "ID")
    p.add_argument("--seed", type=int, default=0, help="seed of the resets and the random actions")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- memory
def _status_mb(field: str) -> Optional[float]:
    """A ``Vm*`` line of ``/proc/self/status`` in MB, or ``None`` where there is none (not Linux)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def reset_peak_memory() -> bool:
    """Start counting the peak resident memory afresh (Linux: ``/proc/self/clear_refs``); ``False``
    where that cannot be done, and the peak then counts from the start of the process."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def memory_mb() -> Dict[str, Optional[float]]:
    """``rss_mb``: resident memory of this process now; ``peak_rss_mb``: its peak since
    :func:`reset_peak_memory` (or since the process started), both in MB (``None`` if unknown)."""
    rss = _status_mb("VmRSS")
    peak = _status_mb("VmHWM")
    if peak is None:  # not Linux: the peak of the whole process (KB on Linux, bytes on macOS)
        usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        peak = usage / (1024.0 * 1024.0) if sys.platform == "darwin" else usage / 1024.0
    return {"rss_mb": rss, "peak_rss_mb": peak}


# ----------------------------------------------------------------------------- timing
def bench_single(env_id: str, steps: int, seed: int = 0) -> dict:
    """Time ``steps`` random-action steps through ``gymnasium.make`` with its default wrappers.

    Episodes are reset as they end; the resets are inside the timed loop. Returns the counts,
    rates and memory in a dict (``steps``, ``agent_steps``, ``resets``, ``seconds``,
    ``steps_per_s``, ``rss_mb``, ``peak_rss_mb``, ...; see :func:`memory_mb`).
    """
    import gymnasium as gym
    import numpy as np

    import safe_mapf_envs  # noqa: F401

    peak_reset = reset_peak_memory()
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
    mem = memory_mb()
    env.close()
    return {"env_id": env_id, "agents": 1, "steps": steps, "agent_steps": steps, "resets": resets,
            "seconds": dt, "steps_per_s": steps / dt, "agent_steps_per_s": steps / dt, **mem,
            "peak_since_start": not peak_reset}


def bench_parallel(env_id: str, n_agents: int, steps: int, seed: int = 0, max_cycles: Optional[int] = None) -> dict:
    """Time ``steps`` steps of the PettingZoo parallel env with ``n_agents`` agents taking random actions.

    An episode ends when every agent is done (``max_cycles`` steps at most: the env's default
    when ``None``); the env is then reset inside the timed loop. ``agent_steps`` counts the
    actions of the agents still live at each step. The memory figures are those of the whole
    process with the env made, reset and stepped (``peak_rss_mb`` counts from just before the
    env is made).
    """
    import numpy as np

    import safe_mapf_envs

    kwargs: Dict[str, Any] = {} if max_cycles is None else {"max_cycles": max_cycles}
    peak_reset = reset_peak_memory()
    env = safe_mapf_envs.parallel_env(env_id, n_agents=n_agents, **kwargs)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    agent_steps = 0
    resets = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        if not env.agents:
            env.reset()
            resets += 1
        live = env.agents
        acts = dict(zip(live, rng.uniform(-1, 1, size=(len(live), 2)).astype(np.float32)))
        agent_steps += len(acts)
        env.step(acts)
    dt = time.perf_counter() - t0
    mem = memory_mb()
    env.close()
    return {"env_id": env_id, "agents": n_agents, "steps": steps, "agent_steps": agent_steps, "resets": resets,
            "seconds": dt, "steps_per_s": steps / dt, "agent_steps_per_s": agent_steps / dt, **mem,
            "peak_since_start": not peak_reset}


def _mb(value: Optional[float]) -> str:
    return "n/a" if value is None else f"{value:,.0f} MB"


def run(args: argparse.Namespace) -> int:
    """Time random-action steps of an environment and print steps (or agent-steps) per second,
    with the resident and peak memory of the process.

    Every row times exactly ``--steps`` environment steps (for each agent count of
    ``--agents``), resetting episodes as they end; the resets are part of the timing. The
    memory is the whole process's, read when the timed steps end (``rss_mb``) and at its peak
    since just before the env was made (``peak_rss_mb``; from the start of the process where
    the system cannot restart the count). ``--map FILE`` runs the id's env on that map, read by
    ``GridMap.from_file`` and registered with the id's settings (a missing or malformed file is
    refused before anything is timed).
    """
    import safe_mapf_envs
    from baselines.cli import env_for_map
    from safe_mapf_envs.registration import check_env_id

    check_env_id(args.env_id)
    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    max_cycles = getattr(args, "max_cycles", None)
    map_file = getattr(args, "map_file", None)
    if max_cycles is not None:
        if not args.agents:
            raise ValueError("--max-cycles sets the episode length of the parallel env: give --agents too")
        if max_cycles < 1:
            raise ValueError(f"--max-cycles must be >= 1, got {max_cycles}")
    if args.agents:
        bad = [n for n in args.agents if n < 1]
        if bad:
            raise ValueError(f"--agents must be counts >= 1, got {bad}")
    # a map of one's own: read it (a bad file raises ValueError naming it) and register it with the id's settings
    env_id = env_for_map(args.env_id, map_file)
    if args.agents:
        for n in args.agents:  # an id of this package and room for n agents, before timing anything
            safe_mapf_envs.parallel_env(env_id, n_agents=n).close()
        rows = [bench_parallel(env_id, n, args.steps, args.seed, max_cycles=max_cycles) for n in args.agents]
    else:
        rows = [bench_single(env_id, args.steps, args.seed)]
    for r in rows:
        if map_file:
            r["map"] = str(map_file)
        if max_cycles is not None:
            r["max_cycles"] = max_cycles
    if args.json:
        print(json.dumps(rows if len(rows) > 1 else rows[0], indent=2))
    else:
        for r in rows:
            peak = _mb(r["peak_rss_mb"]) + (" since start" if r["peak_since_start"] else "")
            print(f"{r['env_id']}  agents={r['agents']}  timed {r['steps']} steps ({r['agent_steps']} "
                  f"agent-steps, {r['resets']} resets included) in {r['seconds']:.2f} s: "
                  f"{r['steps_per_s']:,.0f} steps/s, {r['agent_steps_per_s']:,.0f} agent-steps/s; "
                  f"memory {_mb(r['rss_mb'])} resident, {peak} peak")
    return 0
