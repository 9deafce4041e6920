"""``safe-mapf evaluate``: the paper's Table I (and Figure 1) regenerated on a 2D map."""
from __future__ import annotations

import argparse
import json
import math
import time


def register(sub: argparse._SubParsersAction) -> None:
    from baselines.evaluation import DIFFICULTIES
    from baselines.methods import METHODS, PAPER_METHODS

    p = sub.add_parser("evaluate", help="compare the methods on the same problems (Table I, Figure 1)",
                       description=run.__doc__)
    p.add_argument("--env", default="SafeCentralObstacle-v0", help="env id with shipped checkpoints")
    p.add_argument("--unconstrained", default=None, metavar="PATH",
                   help="unconstrained checkpoint (default: the shipped one for --env)")
    p.add_argument("--constrained", default=None, metavar="PATH",
                   help="constrained checkpoint (default: the shipped one for --env)")
    p.add_argument("--agents", type=int, nargs="+", default=[1, 5, 10, 20], metavar="N", help="agent counts")
    p.add_argument("--problems", type=int, default=50, metavar="P", help="problems per difficulty (default 50)")
    p.add_argument("--difficulty", nargs="+", choices=list(DIFFICULTIES), default=list(DIFFICULTIES))
    p.add_argument("--methods", nargs="+", choices=list(METHODS), default=list(METHODS),
                   help=f"default: all; the paper's four are {', '.join(PAPER_METHODS)}")
    p.add_argument("--seed", type=int, default=0, help="seed of the graph nodes and the problems")
    p.add_argument("--nodes", type=int, default=1000, help="buffer graph nodes (default 1000)")
    p.add_argument("--c-max", type=float, default=None,
                   help="edge cost cut-off of the constrained searches (default: the methods' own)")
    p.add_argument("--budget", type=float, default=None, help="risk budget of ours_budget")
    p.add_argument("--max-cycles", type=int, default=300, help="step limit of a run (default 300)")
    p.add_argument("--out", default="results", help="output folder for runs.csv, table.csv, table.md, figure")
    p.add_argument("--figure", action=argparse.BooleanOptionalAction, default=True,
                   help="also draw the trajectory figure (default on)")
    p.add_argument("--json", action="store_true", help="print the aggregate rows as JSON instead of the table")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run each method on the same problems (difficulties easy / medium / hard target the
    largest finite shortest-path distance on the buffer graph divided by 8 / 4 / 2), then write
    per-run rows (runs.csv), the aggregate (table.csv, table.json), a Markdown table laid out like the
    paper's Table I (table.md, printed) and the trajectory figure (figure.png)."""
    from pathlib import Path

    import torch

    from baselines.evaluation import EvaluationSetup, aggregate, evaluate, markdown_table, write_csv
    from baselines.methods import get_methods

    if args.problems < 1 or min(args.agents) < 1:
        raise ValueError("--problems and --agents must be >= 1")
    torch.set_num_threads(1)
    methods = get_methods(dict.fromkeys(args.methods))
    opts = {}
    if args.c_max is not None:
        opts["c_max"] = args.c_max
    methods = [m.with_options(**opts) if m.search and math.isfinite(m.c_max) and opts else m for m in methods]
    if args.budget is not None:
        methods = [m.with_options(budget=args.budget) if m.budget is not None else m for m in methods]
    t0 = time.perf_counter()
    from agents import load_pretrained

    models = {k: load_pretrained(args.env, kind=k, path=getattr(args, k))
              for k in ("unconstrained", "constrained")}
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed, models=models)
    rows = evaluate(setup, methods, args.agents, args.difficulty, args.problems, seed=args.seed,
                    max_cycles=args.max_cycles, progress=not args.no_progress and not args.json)
    agg = aggregate(rows)
    out = Path(args.out)
    write_csv(rows, out / "runs.csv")
    write_csv(agg, out / "table.csv")
    (out / "table.json").write_text(json.dumps(agg, indent=1))
    names = [m.name for m in methods]
    table = markdown_table(agg, names)
    wall = time.perf_counter() - t0
    header = (f"{args.env}: largest cumulative cost over agents, mean ± std over successful runs "
              f"(success rate); {args.problems} problems per cell, seed {args.seed}, {wall:.0f} s\n\n")
    (out / "table.md").write_text(header + table + "\n\nMean cumulative cost over agents:\n\n"
                                  + markdown_table(agg, names, value="mean_cost") + "\n")
    if args.figure:
        from baselines.figures import trajectory_figure

        trajectory_figure(setup, methods, out / "figure.png", seed=args.seed)
    if args.json:
        print(json.dumps(agg))
    else:
        print(header + table)
        print(f"\nwrote {out / 'runs.csv'}, {out / 'table.csv'}, {out / 'table.json'}, {out / 'table.md'}"
              + (f", {out / 'figure.png'}" if args.figure else ""))
    return 0
