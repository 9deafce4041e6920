"""Table I rows of the multi-agent RL baselines beside ours, from the per-run rows of ``safe-mapf evaluate``.

    # the MARL rows on the problems of the committed CenterDot tables (same seed, graph and counts)
    safe-mapf evaluate --env SafeCenterDot-v0 --agents 1 5 10 20 --problems 20 --methods ippo mappo_lag \\
        --no-figure --out examples/table1/marl/centerdot_strict
    safe-mapf evaluate --protocol paper --env SafeCenterDot-v0 --agents 1 5 10 20 --problems 50 \\
        --methods ippo mappo_lag --out examples/table1/marl/centerdot_paper
    python examples/marl_table.py examples/table1/centerdot_strict/runs.csv \\
        examples/table1/marl/centerdot_strict/runs.csv
    python examples/marl_table.py --protocol paper examples/table1/centerdot_paper/runs.csv \\
        examples/table1/marl/centerdot_paper/runs.csv

Every ``runs.csv`` given is read; rows of the same (method, agents, difficulty, problem) must come
from the same problems, which holds when the runs share ``--seed``, ``--nodes`` and (paper protocol)
``--paper-candidates``: problems are drawn from those alone, whatever the methods. ``--protocol
paper`` keeps, per cell, the c_max of ``ours`` that the command itself kept (chosen on the test
problems, as the published code does). Prints the Markdown table of
:func:`baselines.evaluation.markdown_table` (largest cumulative cost over agents, mean ± std over
successful runs, success rate) for ``--methods``.
"""
from __future__ import annotations

import argparse
import math
from typing import Any, Dict, List

from baselines.evaluation import markdown_table
from baselines.metrics import aggregate
from baselines.output import read_rows as read_runs
from baselines.paper_protocol import choose_best_c_max


def read_rows(paths: List[str]) -> List[Dict[str, Any]]:
    """The rows of every ``runs.csv``, with numbers and success parsed."""
    return [r for path in paths for r in read_runs(path)]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="+", help="runs.csv files of safe-mapf evaluate")
    p.add_argument("--protocol", choices=("strict", "paper"), default="strict")
    p.add_argument("--methods", nargs="+", default=["ours", "ippo", "mappo_lag"])
    p.add_argument("--value", default="cost", help="cost (largest over agents) or mean_cost")
    args = p.parse_args()
    rows = [r for r in read_rows(args.runs) if r["method"] in args.methods]
    if args.protocol == "paper" and any(r["method"] == "ours" and math.isfinite(r["c_max"]) for r in rows):
        rows, _ = choose_best_c_max(rows)
    seen = set()
    for r in rows:  # the same run twice (e.g. two copies of one file) would count twice
        key = (r["method"], r["agents"], r["difficulty"], r["problem"])
        if key in seen:
            raise SystemExit(f"two rows for {key}: give each run once")
        seen.add(key)
    methods = [m for m in args.methods if any(r["method"] == m for r in rows)]
    print(markdown_table(aggregate(rows), methods, value=args.value))


if __name__ == "__main__":
    main()
