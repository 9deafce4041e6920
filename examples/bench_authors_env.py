"""Steps per second of ``SafeCentralObstacle-v0`` against the paper authors' ``SafePointEnv``, in one run.

    python examples/bench_authors_env.py                                  # ours only
    python examples/bench_authors_env.py --authors-repo ../safe-visual-mapf \\
        --authors-python ../authors-venv/bin/python                       # both, and the ratio

Ours is ``gymnasium.make("SafeCentralObstacle-v0")`` with Gymnasium's default wrappers. Theirs is
the ``SafePointEnv`` of the code of the paper "Safe Multi-Agent Navigation guided by
Goal-Conditioned Safe Reinforcement Learning" (a checkout given by ``--authors-repo``), built as
their trainer builds it from ``configs/pointenv/config_SafePointEnv.yaml``: the CentralObstacle
map at resize factor 5, their cost function, ``SafeGoalConditionedPointWrapper`` and their
20-step time limit (which resets the episode itself when it runs out). Both take the same
number of uniform random actions per repetition, episodes reset as they end, resets timed too;
the repetitions alternate between the two, and the ratio is of the median rates.

Their code imports the old ``gym`` (0.25) and ``networkx``, ``matplotlib``, ``tqdm``, ``termcolor``
and ``pyyaml``; it runs in a worker process of ``--authors-python`` (default: this interpreter),
so it can live in a virtual environment of its own. If that interpreter has no ``torch``, the one
import that needs it (the CBFS sampler of another wrapper, unused here) is replaced by a
placeholder. Nothing of theirs is copied into this project.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import gymnasium as gym
import numpy as np

import safe_mapf_envs  # noqa: F401  (registers the ids)

ENV_ID = "SafeCentralObstacle-v0"
CONFIG = "configs/pointenv/config_SafePointEnv.yaml"

#: The worker that runs the authors' env: argv = repo, config, seed. It reads a step count per
#: line on stdin and answers one JSON line per count; their own prints go to stderr.
WORKER = r'''
import inspect, json, sys, time, types, warnings
warnings.simplefilter("ignore")
out, sys.stdout = sys.stdout, sys.stderr  # their prints must not mix with the answers
repo, config, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
sys.path.insert(0, repo)
try:
    import numpy as np
    import yaml
    import importlib.util
    if importlib.util.find_spec("torch") is None:
        # torch is needed by one import of safe_wrappers only, for a wrapper not used here
        name = "pud.algos.cbfs.cbfs_eval"
        stub = types.ModuleType(name)
        def sample_precompiled_grid_policies(*args, **kwargs):
            raise RuntimeError("placeholder: torch is not installed")
        stub.sample_precompiled_grid_policies = sample_precompiled_grid_policies
        sys.modules[name] = stub
    from pud.envs.safe_pointenv.safe_wrappers import SafeGoalConditionedPointWrapper, safe_env_load_fn
    with open(config) as f:
        cfg = yaml.safe_load(f)
    accepted = inspect.signature(SafeGoalConditionedPointWrapper.__init__).parameters
    wrapper_kwargs = {k: v for k, v in cfg["wrappers"]["SafeGoalConditionedPointWrapper"].items() if k in accepted}
    np.random.seed(seed)
    env = safe_env_load_fn(cfg["env"], cfg["cost_function"], max_episode_steps=cfg["time_limit"]["max_episode_steps"],
                           gym_env_wrappers=(SafeGoalConditionedPointWrapper,), wrapper_kwargs=[wrapper_kwargs],
                           terminate_on_timeout=False)
    env.reset()
    rng = np.random.default_rng(seed)
    print(json.dumps({"ready": True, "env": cfg["env"], "cost_function": cfg["cost_function"],
                      "max_episode_steps": cfg["time_limit"]["max_episode_steps"]}), file=out, flush=True)
except Exception as exc:
    print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}), file=out, flush=True)
    sys.exit(1)
for line in sys.stdin:
    steps = int(line)
    actions = rng.uniform(-1, 1, size=(steps, 2)).astype(np.float32)
    resets = 0
    t0 = time.perf_counter()
    for a in actions:
        _, _, done, info = env.step(a.copy())  # their step adds noise to the action in place
        if done:
            env.reset()
            resets += 1
        elif info.get("last_step"):
            resets += 1  # their time limit reset the episode inside step
    dt = time.perf_counter() - t0
    print(json.dumps({"steps": steps, "seconds": dt, "resets": resets}), file=out, flush=True)
'''


def time_ours(steps: int, seed: int) -> Dict[str, float]:
    """``steps`` uniform random actions through ``gymnasium.make(ENV_ID)``, episodes reset as they end."""
    env = gym.make(ENV_ID)
    env.reset(seed=seed)
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
    return {"steps": steps, "seconds": dt, "resets": resets}


class AuthorsWorker:
    """The authors' env in a worker process of ``python`` (see :data:`WORKER`)."""

    def __init__(self, python: str, repo: Path, seed: int) -> None:
        config = repo / CONFIG
        if not (repo / "pud" / "envs" / "safe_pointenv" / "safe_pointenv.py").is_file() or not config.is_file():
            raise SystemExit(f"--authors-repo {repo}: not a checkout of the authors' code "
                             f"(no pud/envs/safe_pointenv/safe_pointenv.py or {CONFIG})")
        self.proc = subprocess.Popen([python, "-c", WORKER, str(repo), str(config), str(seed)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True)
        self.info = self._answer()
        if "error" in self.info:
            raise SystemExit(f"the authors' env did not start under {python}: {self.info['error']}\n"
                             "install their dependencies there (gym==0.25.2, numpy<2, networkx, matplotlib, tqdm, "
                             "termcolor, pyyaml) or pass --authors-python")

    def _answer(self) -> dict:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            return {"error": f"the worker exited (code {self.proc.wait()})"}
        return json.loads(line)

    def time(self, steps: int) -> Dict[str, float]:
        """Run ``steps`` random-action steps there and return what it timed."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{steps}\n")
        self.proc.stdin.flush()
        out = self._answer()
        if "error" in out:
            raise SystemExit(f"the authors' env failed: {out['error']}")
        return out

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.wait(timeout=60)


def _rate(r: Dict[str, float]) -> float:
    return r["steps"] / r["seconds"]


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--steps", type=int, default=5000, help="random-action steps per repetition, for each env")
    p.add_argument("--repeats", type=int, default=3, help="repetitions, alternating between the two envs")
    p.add_argument("--seed", type=int, default=0, help="seed of the resets and the random actions")
    p.add_argument("--authors-repo", type=Path, default=None,
                   help="a checkout of the authors' code (github.com/virajparimi/safe-visual-mapf)")
    p.add_argument("--authors-python", default=sys.executable,
                   help="the Python interpreter that imports their code and its dependencies")
    args = p.parse_args(argv)
    if args.steps < 1 or args.repeats < 1:
        p.error("--steps and --repeats must be positive")

    worker = AuthorsWorker(args.authors_python, args.authors_repo, args.seed) if args.authors_repo else None
    if worker is not None:
        print(f"theirs: SafePointEnv {worker.info['env']}, cost {worker.info['cost_function']}, "
              f"{worker.info['max_episode_steps']}-step episodes", flush=True)
    ours: List[float] = []
    theirs: List[float] = []
    try:
        for k in range(args.repeats):
            r = time_ours(args.steps, args.seed + k)
            ours.append(_rate(r))
            line = f"repetition {k + 1}: ours {ours[-1]:9,.0f} steps/s ({r['resets']} resets)"
            if worker is not None:
                t = worker.time(args.steps)
                theirs.append(_rate(t))
                line += f"   theirs {theirs[-1]:9,.0f} steps/s ({t['resets']} resets)"
            print(line, flush=True)
    finally:
        if worker is not None:
            worker.close()
    mine = statistics.median(ours)
    print(f"{ENV_ID} (gymnasium.make, default wrappers): {mine:,.0f} steps/s (median of {args.repeats})")
    if worker is None:
        print("for the ratio to the authors' SafePointEnv, pass --authors-repo DIR (a checkout of their code) and "
              "--authors-python PYTHON (an interpreter with their dependencies: gym==0.25.2, numpy<2, networkx, "
              "matplotlib, tqdm, termcolor, pyyaml)")
        return 0
    other = statistics.median(theirs)
    print(f"authors' SafePointEnv: {other:,.0f} steps/s (median of {args.repeats})")
    print(f"ratio ours / theirs: {mine / other:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
