"""Benchmark the planning half on the replay-buffer graph of ``SafeCentralObstacle-v0``.

Prints, with the shipped unconstrained checkpoint and one torch thread:

- the time to build the graph for N observations with the full critic ensembles (3 distance
  + 3 cost critics; D and C for all N^2 pairs, then pruning at d_max = 7);
- for K agents on that graph (learned proximity radius 1.5, no cost pruning, durative edges):
  median and worst planning time over P problems (hard difficulty), the status counts, the
  median sum of costs and the makespans of the plans, per solver, without the planner's fallback:

  - ``auto``: the planner's default (ECBS w = 1.1 up to 20 agents, prioritised planning with
    safe intervals above, the large-neighbourhood repair where ECBS runs out of its budget, the
    priority inheritance stepper where prioritised planning gives up);
  - ``prioritized``: prioritised planning alone;
  - ``lns``: the large-neighbourhood repair alone (a prioritised plan whose stuck agents take
    their least conflicting paths, then small groups of agents re-planned until no conflict is
    left);
  - ``pibt``: the priority inheritance stepper alone (all agents step together; an agent in the
    way of a more urgent one is pushed off its node);
  - ``ecbs``: ECBS w = 1.1; ``cbs``: optimal CBS; ``cbs-unit``: optimal CBS with unit-time
    edges (the paper's time model: every edge one step).

  For each solver other than ``ecbs`` that ran beside it, the ratio of its sum of costs to
  ECBS's on the problems both solved (median and worst). ``--agents max`` stands for the most
  agents the problem generator can place in each of the P problems at that difficulty (found by
  bisection, which takes minutes).

Planning time includes attaching the starts and goals with the critics; the median of the
solver's share (after the attachment) and the median CPU time of the whole call (this process's
time, one thread: about what an idle core takes, on a loaded machine) are printed beside it. The
machine's load average is printed first: every solver call is budgeted in expansions (the
planner's default ``expansion_limit``), so the statuses and costs do not depend on the load, but
the times do.

Run: ``python examples/bench_buffer_planner.py [--nodes 1000] [--agents 20 100 200 max] [--problems 20]
[--solvers auto ecbs]``
"""
from __future__ import annotations

import argparse
import collections
import os
import time
from typing import Dict, List

import numpy as np
import torch

from agents.search.graph.build import WaypointGraph
from baselines.evaluation import EvaluationSetup, make_problems

SOLVER_OPTIONS = {
    "auto": dict(solver="auto"),
    "prioritized": dict(solver="prioritized"),
    "lns": dict(solver="lns"),
    "pibt": dict(solver="pibt"),
    "ecbs": dict(solver="cbs", suboptimality=1.1),
    "cbs": dict(solver="cbs", suboptimality=1.0),
    "cbs-unit": dict(solver="cbs", suboptimality=1.0, time_model="unit"),
}


def most_agents(setup: EvaluationSetup, difficulty: str, n_problems: int, seed: int, lo: int = 1,
                hi: int = 512) -> int:
    """The most agents :func:`make_problems` places in each of ``n_problems`` problems (bisection)."""
    def fits(k: int) -> bool:
        try:
            make_problems(setup, difficulty, k, n_problems, seed=seed)
            return True
        except RuntimeError:
            return False

    while lo < hi:
        mid = (lo + hi + 1) // 2
        if fits(mid):
            lo = mid
        else:
            hi = mid - 1
    return lo


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--agents", nargs="+", default=["20"], help="agent counts, or 'max'")
    ap.add_argument("--problems", type=int, default=20)
    ap.add_argument("--difficulty", default="hard")
    ap.add_argument("--solvers", nargs="+", default=["auto", "ecbs"], choices=sorted(SOLVER_OPTIONS))
    ap.add_argument("--time-limit", type=float, default=120.0,
                    help="seconds per solver call: a safety net behind the planner's expansion budget")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")

    setup = EvaluationSetup.build(n_nodes=args.nodes, seed=args.seed)
    agent = setup.models["unconstrained"]
    builds = []
    for _ in range(3):
        t = time.perf_counter()
        graph = WaypointGraph.from_agent(agent, setup.observations, d_max=7.0)
        builds.append(time.perf_counter() - t)
    print(f"graph build, N={args.nodes}: {min(builds):.2f} s (best of 3; {graph.n_edges} edges, "
          f"{graph.n_edges / args.nodes:.0f} per node)")

    counts = []
    for a in args.agents:
        if a == "max":
            k = most_agents(setup, args.difficulty, args.problems, args.seed)
            print(f"most agents placed in {args.problems} problems at difficulty {args.difficulty}: {k}")
            counts.append(k)
        else:
            counts.append(int(a))
    for k in counts:
        problems = make_problems(setup, args.difficulty, k, args.problems, seed=args.seed)
        socs: Dict[str, List[float]] = {}
        for name in args.solvers:
            planner = setup.planner.with_options(time_limit=args.time_limit, fallback_suboptimality=None,
                                                 **SOLVER_OPTIONS[name])
            times, cpu, solver_times, status, spans = [], [], [], collections.Counter(), []
            socs[name] = []
            for p in problems:
                c0 = time.process_time()
                plan = planner.plan(setup.observations[p.start_nodes], setup.observations[p.goal_nodes])
                cpu.append(time.process_time() - c0)
                times.append(plan.planning_time)
                solver_times.append(plan.cbs.runtime_s if plan.cbs is not None else np.nan)
                status[plan.status] += 1
                socs[name].append(plan.soc if plan.solved else np.nan)
                if plan.solved:
                    spans.append(plan.makespan)
            solved = np.array(socs[name], dtype=float)
            soc = (f"median SOC {np.nanmedian(solved):.0f}, makespan median {np.median(spans):.0f} "
                   f"(range {min(spans)}-{max(spans)})" if spans else "no plan")
            print(f"{name}, {k} agents, {args.difficulty}: median {np.median(times):.2f} s, "
                  f"worst {max(times):.2f} s (limit {args.time_limit:g} s; solver median "
                  f"{np.nanmedian(solver_times):.2f} s; CPU median {np.median(cpu):.2f} s, worst {max(cpu):.2f} s), "
                  f"{dict(status)}, {soc}", flush=True)
        if "ecbs" in socs:
            ref = np.array(socs["ecbs"], dtype=float)
            for name, vals in socs.items():
                both = np.isfinite(ref) & np.isfinite(np.array(vals, dtype=float))
                if name != "ecbs" and both.any():
                    r = np.array(vals, dtype=float)[both] / ref[both]
                    print(f"  {name} / ecbs sum of costs, {k} agents, {both.sum()} problems both solved: "
                          f"median {np.median(r):.3f}, worst {r.max():.3f}")


if __name__ == "__main__":
    main()
