"""Why agents did not arrive, across evaluation folders: the reasons per cell, before and after.

Reads the ``runs.csv`` that ``safe-mapf evaluate`` writes into each folder (one folder per apartment,
or the same apartments under two settings) and prints, per folder, the success rate and the reasons
of the failed agents per (method, agents, difficulty) cell, with the totals; ``--figure`` draws the
stacked bars of every folder in one picture.

    python examples/failure_anatomy.py examples/table2/apt0 examples/table2/apt1 --figure anatomy.png
    python examples/failure_anatomy.py before/apt1 after/apt1 --labels before after --problems 10 --methods ours
"""
from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Dict, List

from baselines.anatomy import REASONS, anatomy_table, failure_summary


def read_rows(folder: Path) -> List[Dict[str, str]]:
    path = folder / "runs.csv"
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist (run safe-mapf evaluate --out {folder} first)")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and "failures" not in rows[0]:
        raise SystemExit(f"error: {path} has no failures column: it was written before the failure anatomy existed")
    return rows


def totals(summary) -> Dict[str, int]:
    out = {k: sum(c[k] for c in summary) for k in ("runs", "failed_runs", "failed_agents", *REASONS)}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("folders", nargs="+", type=Path, help="evaluation output folders (each with runs.csv)")
    p.add_argument("--labels", nargs="+", default=None, help="a name per folder (default: the folder names)")
    p.add_argument("--figure", type=Path, default=None, help="write the stacked bars of every folder to this PNG")
    p.add_argument("--problems", type=int, default=None, metavar="N",
                   help="only the first N problems of each cell (the same problems in runs with more per cell)")
    p.add_argument("--methods", nargs="+", default=None, help="only these methods (default: all)")
    args = p.parse_args(argv)
    labels = args.labels or [str(f) for f in args.folders]
    if len(labels) != len(args.folders):
        p.error(f"{len(args.folders)} folders but {len(labels)} labels")
    summaries = []
    for folder, label in zip(args.folders, labels):
        rows = [r for r in read_rows(folder) if (args.problems is None or int(r["problem"]) < args.problems)
                and (args.methods is None or r["method"] in args.methods)]
        summary = failure_summary(rows)
        summaries.append(summary)
        t = totals(summary)
        n = t["failed_agents"]
        shares = ", ".join(f"{k} {t[k]} ({100 * t[k] / n:.0f}%)" for k in REASONS if t[k]) if n else "none"
        print(f"## {label}: {t['runs'] - t['failed_runs']}/{t['runs']} runs succeeded; {n} agents failed: {shares}\n")
        print(anatomy_table(summary) + "\n")
    if args.figure is not None:
        from baselines.anatomy import anatomy_figure

        combined = [{**c, "method": f"{label}: {c['method']}"} for label, s in zip(labels, summaries) for c in s]
        anatomy_figure(combined, args.figure)
        print(f"wrote {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
