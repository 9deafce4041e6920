"""Benchmark the planning half on the replay-buffer graph of ``SafeCentralObstacle-v0``.

Prints, with the shipped unconstrained checkpoint and one torch thread:

- the time to build the graph for N observations with the full critic ensembles (3 distance
  + 3 cost critics; D and C for all N^2 pairs, then pruning at d_max = 7);
- CBS for K agents on that graph (learned proximity radius 1.5, no cost pruning): median and
  worst planning time over P problems (hard difficulty), with the status counts, for optimal
  CBS and ECBS with w = 1.1 (the planner's default) with durative edges, and for optimal CBS
  with unit-time edges (the paper's time model: every edge one step), all without the
  planner's fallback. Planning time includes attaching the starts and goals with the critics.

Run: ``python examples/bench_buffer_planner.py [--nodes 1000] [--agents 5 10 20] [--problems 20]``
"""
from __future__ import annotations

import argparse
import collections
import time

import numpy as np
import torch

from agents.search.graph import WaypointGraph
from baselines.evaluation import EvaluationSetup, make_problems


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--agents", type=int, nargs="+", default=[20])
    ap.add_argument("--problems", type=int, default=20)
    ap.add_argument("--difficulty", default="hard")
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)

    setup = EvaluationSetup.build(n_nodes=args.nodes, seed=args.seed)
    agent = setup.models["unconstrained"]
    builds = []
    for _ in range(3):
        t = time.perf_counter()
        graph = WaypointGraph.from_agent(agent, setup.observations, d_max=7.0)
        builds.append(time.perf_counter() - t)
    print(f"graph build, N={args.nodes}: {min(builds):.2f} s (best of 3; {graph.n_edges} edges, "
          f"{graph.n_edges / args.nodes:.0f} per node)")

    for k in args.agents:
        problems = make_problems(setup, args.difficulty, k, args.problems, seed=args.seed)
        for w, time_model in ((1.0, "durative"), (1.1, "durative"), (1.0, "unit")):
            planner = setup.planner.with_options(suboptimality=w, time_limit=args.time_limit,
                                                 fallback_suboptimality=None, time_model=time_model)
            times, status = [], collections.Counter()
            for p in problems:
                plan = planner.plan(setup.observations[p.start_nodes], setup.observations[p.goal_nodes])
                times.append(plan.planning_time)
                status[plan.status] += 1
            name = ("optimal CBS" if w == 1.0 else f"ECBS w={w}") + f", {time_model} edges"
            print(f"{name}, {k} agents, {args.difficulty}: median {np.median(times):.2f} s, "
                  f"worst {max(times):.2f} s (limit {args.time_limit:g} s), {dict(status)}")


if __name__ == "__main__":
    main()
