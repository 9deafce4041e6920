"""``safe-mapf mapf``: solve a MovingAI grid MAPF instance with a solver of the registry (CBS / ECBS by default)."""
from __future__ import annotations

import argparse
import dataclasses
import json

#: the solver names (:data:`agents.search.mapf.SOLVERS`), listed here so that the help needs no solver import
SOLVER_NAMES = ("cbs", "lacam", "prioritized", "lns", "pibt", "auto")
#: option -> the solver configuration field it sets (an option the chosen solver does not read is refused)
OPTION_FIELDS = {"--suboptimality": "suboptimality", "--heuristic": "heuristic", "--vanilla": "vanilla",
                 "--node-limit": "node_limit", "--memory-limit": "memory_limit_mb", "--expansion-limit": "work_limit",
                 "--seed": "seed", "--first-solution": "anytime"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mapf", help="solve a MovingAI MAPF instance with Conflict-Based Search or another solver",
                       description=run.__doc__)
    p.add_argument("map", metavar="MAP", help="MovingAI .map file (free cells . G S, blocked @ O T W)")
    p.add_argument("scen", metavar="SCEN", help="MovingAI .scen file (its first K agents are used)")
    p.add_argument("--agents", "-k", type=int, required=True, metavar="K", help="number of agents")
    p.add_argument("--solver", choices=SOLVER_NAMES, default="cbs",
                   help="cbs: optimal CBS, or ECBS with --suboptimality (default); lacam: the complete, anytime "
                        "search over joint configurations; prioritized: prioritised planning with safe intervals; "
                        "lns: the large-neighbourhood repair; pibt: the priority inheritance stepper; auto: cbs up "
                        "to 20 agents, then lns if it times out, prioritized above, then pibt if it gives up "
                        "(agents.search.mapf.solve)")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="seconds (default 60); a safety net beside the work budgets")
    p.add_argument("--suboptimality", type=float, default=1.0, metavar="W",
                   help="cbs: 1 for optimal CBS (default); W > 1 runs ECBS with cost <= W x optimal")
    p.add_argument("--heuristic", choices=("wdg", "dg", "cg", "none"), default="wdg",
                   help="high-level heuristic of optimal CBS (default wdg)")
    p.add_argument("--vanilla", action="store_true",
                   help="plain CBS: no conflict prioritisation, bypass, target reasoning or heuristic")
    p.add_argument("--node-limit", type=int, default=None, metavar="N", help="cbs: high-level expansion limit")
    p.add_argument("--expansion-limit", type=int, default=None, metavar="N",
                   help="the work budget of one solver call in its own unit (cbs: low-level expansions, none by "
                        "default; lacam: candidate moves, constraints and repaired edges, default "
                        "agents.search.mapf.lacam.DEFAULT_LACAM_EXPANSION_LIMIT; the others: their planner budgets "
                        "per agent by default); the same budget stops at the same point on any machine")
    p.add_argument("--seed", type=int, default=0, help="lacam, lns: seeds their tie-breaks and draws (default 0)")
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
    swap conflicts, agents stay at their goal, sum of costs) with a solver of the registry
    (``--solver``: CBS / ECBS by default, the LaCAM* search, prioritised planning, the
    large-neighbourhood repair, the priority inheritance stepper or the ``auto`` cascade) and
    report status, sum of costs, makespan, runtime, the work counted and the solver's statistics.
    Exit code 0 when solved, 1 otherwise, 2 when a file or an option is refused (with a message
    saying why; a file's names the file and line)."""
    from agents.search.mapf import (
        DEFAULT_MEMORY_LIMIT_MB,
        SOLVERS,
        MapfInstance,
        SolverConfig,
        load_instance,
        solve,
        validate,
    )
    from agents.search.mapf.lacam import DEFAULT_LACAM_EXPANSION_LIMIT

    if args.agents < 1:
        raise ValueError(f"--agents must be >= 1, got {args.agents}")
    reads = SOLVERS[args.solver].reads
    given = {"--suboptimality": args.suboptimality != 1.0, "--heuristic": args.heuristic != "wdg",
             "--vanilla": args.vanilla, "--node-limit": args.node_limit is not None,
             "--memory-limit": args.memory_limit is not None, "--expansion-limit": args.expansion_limit is not None,
             "--seed": args.seed != 0, "--first-solution": args.first_solution}
    for flag, field in OPTION_FIELDS.items():
        if given[flag] and field not in reads:
            raise ValueError(f"{flag} does not apply to --solver {args.solver}")
    inst = load_instance(args.map, args.scen, args.agents)
    work_limit = args.expansion_limit
    if work_limit is None and args.solver == "lacam":
        work_limit = DEFAULT_LACAM_EXPANSION_LIMIT
    memory = DEFAULT_MEMORY_LIMIT_MB if args.memory_limit is None else (args.memory_limit or None)
    # no CBS work budget and no second, looser CBS call unless asked: the time limit ends a hard search
    config = SolverConfig(name=args.solver, suboptimality=args.suboptimality, fallback_suboptimality=None,
                          expansion_limit=None, node_limit=args.node_limit, work_limit=work_limit,
                          time_limit=args.time_limit, seed=args.seed, heuristic=args.heuristic,
                          vanilla=bool(args.vanilla), memory_limit_mb=memory, anytime=not args.first_solution)
    # grid coordinates switch rectangle reasoning on (vanilla CBS ignores them)
    res = solve(MapfInstance(inst.graph, inst.starts, inst.goals), config, grid_coords=inst.cells)
    violations = (validate(inst.graph, inst.starts, inst.goals, res.paths)
                  if res.solved and res.paths is not None else None)
    out = {
        "map": args.map,
        "scen": args.scen,
        "agents": args.agents,
        "solver": args.solver,
        "solver_used": res.solver,
        "status": res.status,
        "soc": res.soc,
        "makespan": res.makespan,
        "lower_bound": res.lower_bound,
        "runtime_s": round(res.runtime_s, 4),
        "work": res.work,
        "stats": None if res.stats is None else dataclasses.asdict(res.stats),
        "suboptimality": args.suboptimality if "suboptimality" in reads else None,
        "vanilla": bool(args.vanilla),
        "expansion_limit": work_limit,
        "seed": args.seed if "seed" in reads else None,
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
        used = args.solver if res.solver == args.solver else f"{args.solver} ({res.solver})"
        print(f"{inst.grid.name}, {args.agents} agents, {used}: {res.status} (soc {soc}, makespan {span}) "
              f"in {res.runtime_s:.2f} s, work {res.work}")
        if res.message:
            print(f"  {res.message}")
        if violations:
            print(f"  INVALID: {violations[0]}")
        if out.get("paths_out"):
            print(f"  paths written to {args.paths_out}")
    if violations:
        return 1
    return 0 if res.solved else 1
