"""``safe-mapf mapf``: solve a MovingAI grid MAPF instance with CBS (or ECBS) or the LaCAM* search."""
from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mapf", help="solve a MovingAI MAPF instance with Conflict-Based Search or LaCAM*",
                       description=run.__doc__)
    p.add_argument("map", metavar="MAP", help="MovingAI .map file (free cells . G S, blocked @ O T W)")
    p.add_argument("scen", metavar="SCEN", help="MovingAI .scen file (its first K agents are used)")
    p.add_argument("--agents", "-k", type=int, required=True, metavar="K", help="number of agents")
    p.add_argument("--solver", choices=("cbs", "lacam"), default="cbs",
                   help="cbs: optimal CBS, or ECBS with --suboptimality (default); lacam: the complete, anytime "
                        "search over joint configurations (agents.search.mapf.solve_lacam)")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="seconds (default 60); lacam: a safety net beside --expansion-limit")
    p.add_argument("--suboptimality", type=float, default=1.0, metavar="W",
                   help="cbs: 1 for optimal CBS (default); W > 1 runs ECBS with cost <= W x optimal")
    p.add_argument("--heuristic", choices=("wdg", "dg", "cg", "none"), default="wdg",
                   help="high-level heuristic of optimal CBS (default wdg)")
    p.add_argument("--vanilla", action="store_true",
                   help="plain CBS: no conflict prioritisation, bypass, target reasoning or heuristic")
    p.add_argument("--node-limit", type=int, default=None, metavar="N", help="cbs: high-level expansion limit")
    p.add_argument("--expansion-limit", type=int, default=None, metavar="N",
                   help="lacam: the work budget (candidate moves, constraints and repaired edges; default "
                        "agents.search.mapf.lacam.DEFAULT_LACAM_EXPANSION_LIMIT); the same budget stops at the "
                        "same point on any machine")
    p.add_argument("--seed", type=int, default=0, help="lacam: seeds its tie-breaks (default 0)")
    p.add_argument("--first-solution", action="store_true",
                   help="lacam: stop at the first solution instead of improving it until the budget ends")
    p.add_argument("--memory-limit", type=float, default=None, metavar="MIB",
                   help="stop with status timeout once the search has grown the process by this many MiB "
                        "(default: the solver's, agents.search.mapf.DEFAULT_MEMORY_LIMIT_MB; 0 turns the guard off)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--paths-out", default=None, metavar="FILE",
                   help="write the paths as JSON: per agent, [row, col] at every time step until its final arrival")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Solve the first K agents of a MovingAI scenario (4-connected moves and waits, vertex and
    swap conflicts, agents stay at their goal, sum of costs) with CBS / ECBS (``--solver cbs``)
    or the LaCAM* search (``--solver lacam``: complete and anytime; hundreds of agents) and
    report status, sum of costs, makespan, runtime and search statistics. Exit code 0 when
    solved, 1 otherwise, 2 when a file or an option is refused (with a message saying why; a
    file's names the file and line)."""
    from agents.search.mapf import (
        DEFAULT_MEMORY_LIMIT_MB,
        MapfInstance,
        load_instance,
        solve_cbs,
        solve_lacam,
        validate,
    )
    from agents.search.mapf.lacam import DEFAULT_LACAM_EXPANSION_LIMIT

    if args.agents < 1:
        raise ValueError(f"--agents must be >= 1, got {args.agents}")
    lacam = args.solver == "lacam"
    misplaced = ([("--suboptimality", args.suboptimality != 1.0), ("--heuristic", args.heuristic != "wdg"),
                  ("--vanilla", args.vanilla), ("--node-limit", args.node_limit is not None),
                  ("--memory-limit", args.memory_limit is not None)] if lacam else
                 [("--expansion-limit", args.expansion_limit is not None), ("--seed", args.seed != 0),
                  ("--first-solution", args.first_solution)])
    for flag, given in misplaced:
        if given:
            raise ValueError(f"{flag} does not apply to --solver {args.solver}")
    inst = load_instance(args.map, args.scen, args.agents)
    if lacam:
        budget = DEFAULT_LACAM_EXPANSION_LIMIT if args.expansion_limit is None else args.expansion_limit
        res = solve_lacam(MapfInstance(inst.graph, inst.starts, inst.goals), expansion_limit=budget,
                          time_limit=args.time_limit, seed=args.seed, anytime=not args.first_solution)
    else:
        memory = DEFAULT_MEMORY_LIMIT_MB if args.memory_limit is None else (args.memory_limit or None)
        # grid coordinates switch rectangle reasoning on (vanilla CBS ignores them)
        res = solve_cbs(inst.graph, inst.starts, inst.goals, time_limit=args.time_limit,
                        suboptimality=args.suboptimality, node_limit=args.node_limit,
                        memory_limit_mb=memory,
                        vanilla=args.vanilla, heuristic=args.heuristic, grid_coords=inst.cells)
    violations = (validate(inst.graph, inst.starts, inst.goals, res.paths)
                  if res.solved and res.paths is not None else None)
    out = {
        "map": args.map,
        "scen": args.scen,
        "agents": args.agents,
        "solver": args.solver,
        "status": res.status,
        "soc": res.soc,
        "makespan": res.makespan,
        "lower_bound": res.lower_bound,
        "runtime_s": round(res.stats.runtime_s, 4),
        "hl_expanded": res.stats.hl_expanded,
        "hl_generated": res.stats.hl_generated,
        "ll_expanded": res.stats.ll_expanded,
        "ll_calls": res.stats.ll_calls,
        "suboptimality": None if lacam else args.suboptimality,
        "vanilla": bool(args.vanilla),
        "expansion_limit": budget if lacam else None,
        "seed": args.seed if lacam else None,
        "valid": None if violations is None else not violations,
        "message": res.message,
    }
    if args.paths_out and res.solved:
        with open(args.paths_out, "w") as fh:
            json.dump(inst.to_rowcol(res.node_sequences()), fh)
        out["paths_out"] = args.paths_out
    if args.json:
        print(json.dumps(out))
    else:
        soc = "-" if res.soc is None else res.soc
        span = "-" if res.makespan is None else res.makespan
        what = "configurations" if lacam else "high-level expansions"
        count = res.stats.hl_generated if lacam else res.stats.hl_expanded
        print(f"{inst.grid.name}, {args.agents} agents, {args.solver}: {res.status} (soc {soc}, makespan {span}) "
              f"in {res.stats.runtime_s:.2f} s, {count} {what}")
        if res.message:
            print(f"  {res.message}")
        if violations:
            print(f"  INVALID: {violations[0]}")
        if out.get("paths_out"):
            print(f"  paths written to {args.paths_out}")
    if violations:
        return 1
    return 0 if res.solved else 1
