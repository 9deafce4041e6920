"""Where the largest cost goes: the costliest agent's cost per activity, per evaluation cell.

Reads the ``runs.csv`` that ``safe-mapf evaluate`` writes into each folder and prints, per folder,
the mean largest cumulative cost of the successful runs per (method, agents, difficulty) cell,
split by what the costliest agent was doing when it paid it (driven by its policy or the fallback,
escaping, or standing still for the plan's times, the plan's order, its parking, another agent's
goal or a yield; :mod:`baselines.cost_anatomy`); ``--summary`` adds the parts averaged over the
cells per method; ``--figure`` draws the stacked bars.

    python examples/cost_anatomy.py examples/table2/heldout_s4/apt3 --agents 5 10 --figure cost.png
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agents.search.execution.stats import ACTIVITIES
from baselines.cost_anatomy import cost_anatomy, cost_anatomy_figure, cost_anatomy_table
from baselines.output import read_rows


def over_cells(summary):
    """Per method, the cells' parts averaged (one row each, difficulty ``all``, agents the cells' largest)."""
    out = []
    for m in dict.fromkeys(c["method"] for c in summary):
        cells = [c for c in summary if c["method"] == m]
        mean = {a: sum(c[a] for c in cells) / len(cells) for a in (*ACTIVITIES, "cost")}
        out.append({"method": m, "difficulty": "all", "agents": max(c["agents"] for c in cells),
                    "runs": sum(c["runs"] for c in cells), **mean})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("folders", nargs="+", type=Path, help="evaluation output folders (each with runs.csv)")
    p.add_argument("--methods", nargs="+", default=None, help="only these methods (default: all)")
    p.add_argument("--agents", nargs="+", type=int, default=None, help="only these agent counts (default: all)")
    p.add_argument("--figure", type=Path, default=None, help="save the stacked bars of all folders here")
    p.add_argument("--summary", action="store_true",
                   help="also print, per folder and method, the parts averaged over the chosen cells")
    args = p.parse_args(argv)
    every = []
    for folder in args.folders:
        path = folder / "runs.csv"
        if not path.is_file():
            raise SystemExit(f"error: {path} does not exist (run safe-mapf evaluate --out {folder} first)")
        rows = read_rows(path)
        if rows and "cost_split" not in rows[0]:
            raise SystemExit(f"error: {path} has no cost_split column: it was written before the cost anatomy existed")
        rows = [r for r in rows if (args.methods is None or r["method"] in args.methods)
                and (args.agents is None or r["agents"] in args.agents)]
        summary = cost_anatomy(rows)
        if not summary:
            raise SystemExit(f"error: {path} has no successful run with a cost split among the chosen cells")
        print(f"## {folder}\n\n{cost_anatomy_table(summary)}\n")
        if args.summary:
            print(f"{cost_anatomy_table(over_cells(summary))}\n")
        every += [{**c, "method": f"{folder.name}:{c['method']}" if len(args.folders) > 1 else c["method"]}
                  for c in summary]
    if args.figure is not None:
        print(f"wrote {cost_anatomy_figure(every, args.figure)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
