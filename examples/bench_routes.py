"""The agents themselves, on the routes plans give them: per-hop and per-route success, open loop.

A plan hands an agent a route of waypoints. This benchmark asks how well each shipped agent (or
the ones given) drives such routes with nothing else to help it: no localisation, no progress
rule, no replanning, no fallback. On held-out single-agent problems (graph and problems drawn from
``--seed``, which the published tables do not use), ours' planner gives each problem its route
(``c_max`` as given); each agent then drives

- every **hop** of every route alone, from the exact position of one waypoint to the next
  (success within ``--hop-steps`` steps, 20 by default, and the hop's cost);
- every **route** open loop from its start, in two ways: moving on to the next waypoint once its
  own critic puts it within 2 steps (``critic``: the rule of the published code of the paper),
  and once it is truly within the env's goal threshold of it (``reach``: ground truth, which
  isolates driving from the critic's judgement). A route succeeds when the agent reaches its goal
  within ``--max-steps`` (300) steps.

Per difficulty and agent the table shows hops and their success and mean cost, route success both
ways, the mean cost of the routes that arrived (critic rule), how far from a waypoint (world units)
the agent was on average when the critic rule moved it on ("passed at"; the env's goal threshold
is the scale: 1 unit on the grid maps, 0.5 m in the apartments) and on which leg the failed routes
ended (first, a middle one, last).

    python examples/bench_routes.py --env SafeApartment0-v0 --c-max-from examples/table2/apt0/c_max.json \
        --routes 30 --out routes/apt0
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Dict, List

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

AGENTS = ("unconstrained", "constrained")


def route_positions(setup: Any, plan: Any, start: int, goal: int) -> Any:
    """World positions of a single-agent plan's route: the start, its buffer waypoints and the goal."""
    import numpy as np

    n = len(setup.observations)
    nodes = [v for v in plan.nodes[0] if v < n]  # buffer waypoints (the start and goal ids lie beyond n)
    return np.stack([setup.states[start]] + [setup.states[v] for v in nodes] + [setup.states[goal]])


def summarize(hops: Dict[str, Any], critic: Dict[str, Any], reach: Dict[str, Any]) -> Dict[str, Any]:
    """One table row from the hop and the two route runs of an agent."""
    import numpy as np

    failed = ~critic["success"]
    at, n_hops = critic["stuck_at"][failed], critic["hops"][failed]
    advanced = int(critic["advanced"].sum())
    return {
        "routes": int(len(critic["success"])),
        "mean_hops": float(critic["hops"].mean()),
        "hops": int(len(hops["success"])),
        "hop_success": float(hops["success"].mean()),
        "hop_cost": float(hops["cost"].mean()),
        "route_success_critic": float(critic["success"].mean()),
        "route_success_reach": float(reach["success"].mean()),
        "route_cost": float(critic["cost"][critic["success"]].mean()) if critic["success"].any() else float("nan"),
        "pass_distance": (float(np.nansum(critic["pass_distance"] * critic["advanced"]) / advanced) if advanced
                          else float("nan")),
        "failed_first": int((at == 0).sum()),
        "failed_middle": int(((at > 0) & (at < n_hops - 1)).sum()),
        "failed_last": int(((at == n_hops - 1) & (at > 0)).sum()),
    }


def markdown(rows: List[Dict[str, Any]], title: str) -> str:
    head = ("| difficulty | agent | routes (hops each) | hop success | hop cost | route success: critic / reach "
            "| route cost | passed at | failed on leg: first / middle / last |")
    lines = [title, "", head, "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['difficulty']} | {r['agent']} | {r['routes']} ({r['mean_hops']:.1f}) | "
            f"{100 * r['hop_success']:.1f}% of {r['hops']} | {r['hop_cost']:.2f} | "
            f"{100 * r['route_success_critic']:.0f}% / {100 * r['route_success_reach']:.0f}% | "
            f"{r['route_cost']:.2f} | {r['pass_distance']:.2f} | "
            f"{r['failed_first']} / {r['failed_middle']} / {r['failed_last']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="SafeApartment0-v0")
    p.add_argument("--unconstrained", default=None, help="checkpoint of the unconstrained agent (default: shipped)")
    p.add_argument("--constrained", default=None, help="checkpoint of the constrained agent (default: shipped)")
    p.add_argument("--c-max", type=float, default=None,
                   help="ours' cost cut-off for the routes (default: the method's, 0.25)")
    p.add_argument("--c-max-from", type=Path, default=None,
                   help="a c_max.json of safe-mapf evaluate: the cut-off chosen there for one agent")
    p.add_argument("--routes", type=int, default=30, help="problems (one route each) per difficulty")
    p.add_argument("--difficulties", nargs="+", default=["easy", "medium", "hard"],
                   choices=("easy", "medium", "hard"))
    p.add_argument("--seed", type=int, default=10002, help="seed of the graph and the problems (a validation seed)")
    p.add_argument("--nodes", type=int, default=1000, help="graph nodes")
    p.add_argument("--hop-steps", type=int, default=20, help="step limit of a hop driven alone")
    p.add_argument("--max-steps", type=int, default=300, help="step limit of a route")
    p.add_argument("--out", type=Path, default=None, help="folder for routes.json and routes.md")
    args = p.parse_args(argv)
    if args.routes < 1 or args.nodes < 2 or args.hop_steps < 1 or args.max_steps < 1:
        p.error("--routes, --hop-steps and --max-steps must be >= 1 and --nodes >= 2")
    if args.c_max_from is not None:
        if args.c_max is not None:
            p.error("give --c-max or --c-max-from, not both")
        chosen = json.loads(args.c_max_from.read_text()).get("chosen", {})
        if "1" not in chosen:
            p.error(f"{args.c_max_from} has no c_max for one agent (it has {sorted(chosen)})")
        args.c_max = float(chosen["1"])

    import numpy as np
    import torch

    import safe_mapf_envs  # noqa: F401
    from agents import load_pretrained
    from agents.evaluation import run_episodes, run_routes
    from baselines.evaluation import EvaluationSetup, make_problems
    from baselines.methods import METHODS

    torch.set_num_threads(1)
    paths = {"unconstrained": args.unconstrained, "constrained": args.constrained}
    models = {k: load_pretrained(args.env, k, path=paths[k]) for k in AGENTS}
    ours = METHODS["ours"] if args.c_max is None else METHODS["ours"].with_options(c_max=args.c_max)
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed, models=models)
    planner = setup.planner.with_options(**dict(ours.options))
    rows: List[Dict[str, Any]] = []
    for difficulty in args.difficulties:
        problems = make_problems(setup, difficulty, 1, args.routes, seed=args.seed)
        routes = []
        for prob in problems:
            s, g = int(prob.start_nodes[0]), int(prob.goal_nodes[0])
            plan = planner.plan(setup.observations[[s]], setup.observations[[g]])
            if plan.solved:
                routes.append(route_positions(setup, plan, s, g))
        if not routes:
            print(f"{difficulty}: no problem has a route at c_max {ours.c_max:g}")
            continue
        hop_starts = np.concatenate([r[:-1] for r in routes])
        hop_goals = np.concatenate([r[1:] for r in routes])
        for agent in AGENTS:
            hops = run_episodes(models[agent], args.env, hop_starts, hop_goals, max_steps=args.hop_steps)
            critic = run_routes(models[agent], args.env, routes, advance="critic", max_steps=args.max_steps)
            reach = run_routes(models[agent], args.env, routes, advance="reach", max_steps=args.max_steps)
            row = {"difficulty": difficulty, "agent": agent, **summarize(hops, critic, reach)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    title = (f"{args.env}: routes of ours' planner (c_max {ours.c_max:g}, {args.nodes} nodes), one agent, "
             f"seed {args.seed}; hops within {args.hop_steps} steps, routes within {args.max_steps}")
    text = markdown(rows, title)
    print(text)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "routes.json").write_text(json.dumps({"title": title, "rows": rows}, indent=1))
        (args.out / "routes.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
