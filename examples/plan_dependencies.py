"""How much the agents' planned routes share, per search method: the plans alone, no execution.

For each problem, every search method plans the agents' routes on the same graph as ``safe-mapf
evaluate`` (ours with its cost cut-off from a ``c_max.json``) and the plan is counted: graph nodes
that a pair of routes both visit, and the plan-order dependencies the controller derives from
them (an agent waits at a waypoint until the agent the plan sends first has passed). Shared places
are what makes agents hold for one another when one of them runs late (see the cost anatomy,
``examples/cost_anatomy.py``). ``--spread MODE`` plans with the planner's ``spread_routes`` set to
MODE.

    python examples/plan_dependencies.py --env SafeApartment3-v0 --agents 10 --seed 4 --problems 20 \\
        --c-max-from examples/table2/apt3/c_max.json
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    from agents.search.mapf import SPREAD_MODES

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="SafeApartment3-v0", help="a registered env id with shipped agents")
    p.add_argument("--agents", type=int, default=10, help="agents per problem")
    p.add_argument("--difficulty", default="hard", choices=["easy", "medium", "hard"])
    p.add_argument("--seed", type=int, default=0, help="the graph's and the problems' seed, as safe-mapf evaluate's")
    p.add_argument("--problems", type=int, default=20, help="problems to plan")
    p.add_argument("--nodes", type=int, default=1000, help="graph nodes (safe-mapf evaluate's default)")
    p.add_argument("--methods", nargs="+", default=["sorb", "ours"], help="search methods to compare")
    p.add_argument("--c-max-from", type=Path, default=None, help="ours' cut-off per agent count (a c_max.json)")
    p.add_argument("--spread", default=None, choices=SPREAD_MODES,
                   help="the planner's spread_routes: of equal routes, those that pass fewer nodes of other "
                        "routes (routes) or also fewer nodes near them (near); default: the planner's")
    args = p.parse_args(argv)
    if args.agents < 2:
        p.error(f"--agents must be at least 2 to share anything, got {args.agents}")
    if args.problems < 1:
        p.error(f"--problems must be >= 1, got {args.problems}")
    import torch

    import safe_mapf_envs
    from agents.search.config import preset_for
    from agents.search.policy import SearchPolicy
    from baselines.evaluation import EvaluationSetup, make_problems
    from baselines.methods import get_methods

    torch.set_num_threads(1)
    methods = get_methods(args.methods)
    if any(not m.search for m in methods):
        p.error(f"only search methods plan routes; not {[m.name for m in methods if not m.search]}")
    chosen = None
    if args.c_max_from is not None:
        chosen = json.loads(args.c_max_from.read_text())["chosen"].get(str(args.agents))
        if chosen is None:
            p.error(f"{args.c_max_from} has no c_max for {args.agents} agents")
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed)
    problems = make_problems(setup, args.difficulty, args.agents, args.problems, seed=args.seed)
    env = safe_mapf_envs.parallel_env(args.env, n_agents=args.agents, max_cycles=300)
    print(f"{args.env}, {args.difficulty}, {args.agents} agents, {args.problems} problems, seed {args.seed}\n")
    print("| method | shared nodes per plan (pairs of routes) | order dependencies per plan | planned sum of steps |")
    print("|---|---|---|---|")
    for m in methods:
        if chosen is not None and math.isfinite(m.c_max):
            m = m.with_options(c_max=float(chosen))
        if args.spread is not None:
            m = m.with_options(spread_routes=args.spread)
        base = replace(preset_for(setup.models[m.policy]), graph=setup.planner.graph,
                       solver=setup.planner.solver_config)
        shared, deps, soc = [], [], []
        for prob in problems:
            obs, _ = env.reset(seed=args.seed + prob.index, options={"starts": prob.starts, "goals": prob.goals})
            config = m.config(base)
            policy = SearchPolicy(setup.planner.with_configs(config.graph, config.solver), setup.models[m.policy],
                                  controller=config.controller, budget=config.budget, seed=args.seed + prob.index)
            policy.predict({a: obs[a] for a in env.agents})
            plan = policy.current_plan
            routes = [set(x) for x in plan.nodes]
            shared.append(sum(len(routes[i] & routes[j]) for i in range(len(routes))
                              for j in range(i + 1, len(routes))))
            deps.append(sum(len(v) for q in policy.controller.plans.values() for v in (q.after or {}).values()))
            soc.append(plan.soc)
        print(f"| {m.name} | {np.mean(shared):.2f} | {np.mean(deps):.2f} | {np.mean(soc):.1f} |")
    env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
