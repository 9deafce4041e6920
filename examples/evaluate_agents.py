"""Measure the shipped (or given) agents of an environment and print the figures.

    python examples/evaluate_agents.py                          # SafeCentralObstacle-v0
    python examples/evaluate_agents.py --env SafeApartment2-v0
    python examples/evaluate_agents.py --map examples/data/maps/scatter-64-64.map
    python examples/evaluate_agents.py --unconstrained runs/u/model.zip --constrained runs/c/model.zip

On held-out random start-goal pairs drawn with a fixed seed (ground truth is used to pick
and score the pairs, never by the agents):

- success within the 20-step limit and mean episode cost of both agents on the same pairs
  whose geodesic distance is at most 10 units (3 m on the apartments);
- Spearman rank correlation between predicted distance and geodesic distance for pairs
  within 15 units (4 m on the apartments);
- wall and CPU time to build the planner's matrices D and C for 1000 observations
  (10^6 pairs, full ensembles; on the apartments the 1000 panoramas are rendered and encoded
  first, and that is timed too).

Targets (printed next to the figures): success >= 0.95 for both agents (0.9 on the
apartments); Spearman >= 0.9 (0.85); constrained mean cost <= unconstrained mean cost; D and C
in about 5 s (a graph of 1000 panoramas in 10 s).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Optional

import gymnasium as gym
import numpy as np
import torch

import safe_mapf_envs  # noqa: F401
from agents import SafeGoalTD3, load_pretrained
from agents.encoders import is_image_space
from agents.evaluation import distance_rank_correlation, run_episodes, sample_problems
from agents.training import default_eval_distances
from baselines.cli import env_for_map


@dataclass
class Settings:
    """What to measure."""

    env_id: str = "SafeCentralObstacle-v0"
    """environment of the agents"""
    seed: int = 2024
    """seed of the held-out pairs (training and its periodic evaluation use other seeds)"""
    n_episodes: int = 500
    """pairs for the success and cost figures"""
    max_distance: Optional[float] = None
    """largest geodesic distance of those pairs (world units; default 10, 3 m on the apartments)"""
    n_pairs: int = 1000
    """pairs for the distance correlation"""
    pair_max_distance: Optional[float] = None
    """largest geodesic distance of those pairs (default 15, 4 m on the apartments)"""
    n_nodes: int = 1000
    """observations for the D and C timing"""


def mark(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def time_matrices(model: SafeGoalTD3, nodes: np.ndarray, threads: int) -> dict:
    torch.set_num_threads(threads)
    model.pairwise(nodes[:50], nodes[:50])  # warm-up
    out = {}
    w, c = time.perf_counter(), time.process_time()
    model.pairwise(nodes, nodes)
    out["joint"] = (time.perf_counter() - w, time.process_time() - c)
    w, c = time.perf_counter(), time.process_time()
    model.pairwise_distance(nodes, nodes)
    model.pairwise_cost(nodes, nodes)
    out["separate"] = (time.perf_counter() - w, time.process_time() - c)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default=Settings.env_id, help="environment id (default %(default)s)")
    p.add_argument("--map", dest="map_file", default=None, metavar="FILE",
                   help="a map of one's own in place of --env's (see safe-mapf train --map)")
    p.add_argument("--unconstrained", default=None, help="checkpoint (default: the shipped one)")
    p.add_argument("--constrained", default=None, help="checkpoint (default: the shipped one)")
    p.add_argument("--seed", type=int, default=Settings.seed)
    p.add_argument("--episodes", type=int, default=Settings.n_episodes)
    p.add_argument("--skip-timing", action="store_true")
    args = p.parse_args()
    s = Settings(env_id=env_for_map(args.env, args.map_file), seed=args.seed, n_episodes=args.episodes)
    lo, hi = default_eval_distances(s.env_id)
    s.max_distance = lo if s.max_distance is None else s.max_distance
    s.pair_max_distance = hi if s.pair_max_distance is None else s.pair_max_distance
    env = gym.make(s.env_id)
    visual = is_image_space(env.observation_space["observation"])
    success_target, spearman_target = (0.9, 0.85) if visual else (0.95, 0.9)
    torch.set_num_threads(1)

    agents = {
        "unconstrained": load_pretrained(s.env_id, "unconstrained", path=args.unconstrained),
        "constrained": load_pretrained(s.env_id, "constrained", path=args.constrained),
    }
    rng = np.random.default_rng(s.seed)
    starts, goals, _ = sample_problems(env, s.n_episodes, rng, s.max_distance)
    ps, pg, pd = sample_problems(env, s.n_pairs, rng, s.pair_max_distance)

    print(f"{s.env_id}: {s.n_episodes} held-out pairs with geodesic distance <= {s.max_distance:g} "
          f"(seed {s.seed}), 20-step limit")
    results = {}
    for name, model in agents.items():
        ep = run_episodes(model, env, starts, goals)
        corr = distance_rank_correlation(model, env, ps, pg, pd, aggregate="max")
        results[name] = dict(success=ep["success"].mean(), cost=ep["cost"].mean(), steps=ep["steps"].mean(),
                             spearman=corr["spearman"], lam=model.lagrange_multiplier,
                             limit=model.lagrangian.cost_limit)
        r = results[name]
        print(f"  {name:13s} success={r['success']:.3f} [{mark(r['success'] >= success_target)} >= {success_target}]  "
              f"mean episode cost={r['cost']:.3f}  mean steps={r['steps']:.2f}  lambda={r['lam']:.3f}")
    u, c = results["unconstrained"], results["constrained"]
    print(f"  constrained cost {c['cost']:.3f} vs unconstrained {u['cost']:.3f} "
          f"[{mark(c['cost'] <= u['cost'])} no higher]; cost limit {c['limit']:g} "
          f"[{mark(c['cost'] < c['limit'])} under]")
    print(f"Predicted vs geodesic distance, {s.n_pairs} pairs within {s.pair_max_distance:g} units "
          f"(ensemble max):")
    for name, r in results.items():
        ok = mark(r["spearman"] >= spearman_target)
        print(f"  {name:13s} Spearman={r['spearman']:.3f} [{ok} >= {spearman_target}]")

    if not args.skip_timing:
        model = agents["unconstrained"]
        w, c = time.perf_counter(), time.process_time()
        u = env.unwrapped
        nodes = u.observations_at(u.sample_states(s.n_nodes, np.random.default_rng(s.seed + 1)))
        if visual:
            print(f"rendering {s.n_nodes} panoramas: wall {time.perf_counter() - w:.2f} s, "
                  f"cpu {time.process_time() - c:.2f} s")
        print(f"D and C for {s.n_nodes} observations ({s.n_nodes ** 2:.0e} pairs, "
              f"{model.policy.n_critics}+{model.policy.n_cost_critics} critics, aggregate max):")
        limit = 10.0 if visual else 5.0
        for threads in (1, 2):
            t = time_matrices(model, nodes, threads)
            for how, (wall, cpu) in t.items():
                print(f"  torch threads={threads} {how:8s}: wall {wall:.2f} s, cpu {cpu:.2f} s "
                      f"[{mark(wall <= limit)} <= {limit:g} s]")


if __name__ == "__main__":
    main()
