"""Two settings on the same problems, run by run: arrivals gained and lost, and the paired cost change.

Give the evaluation folders of each setting (``safe-mapf evaluate --out ...``, one per apartment,
in the same order); each folder's ``runs.csv`` is paired with its counterpart problem by problem
(``baselines.compare``). Prints one table per pair of folders and, for several, one over all.

    python examples/compare_runs.py --before base/apt0 base/apt1 --after new/apt0 new/apt1 --methods ours
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Dict, List

from baselines.compare import comparison_table, merge, pair_runs
from baselines.output import read_rows


def runs_of(folder: Path) -> List[Dict[str, Any]]:
    path = folder / "runs.csv"
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist (run safe-mapf evaluate --out {folder} first)")
    return read_rows(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", nargs="+", type=Path, required=True, help="evaluation folders of the first setting")
    p.add_argument("--after", nargs="+", type=Path, required=True, help="the same problems under the second")
    p.add_argument("--methods", nargs="+", default=None, help="only these methods (default: all)")
    p.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples of the paired differences")
    args = p.parse_args(argv)
    if len(args.before) != len(args.after):
        p.error(f"{len(args.before)} folders before but {len(args.after)} after: give one of each per evaluation")
    if args.resamples < 1:
        p.error(f"--resamples must be >= 1, got {args.resamples}")
    every = []
    for before, after in zip(args.before, args.after):
        rows = [[r for r in runs_of(f) if args.methods is None or r["method"] in args.methods]
                for f in (before, after)]
        try:
            cells = pair_runs(*rows)
        except ValueError as e:
            raise SystemExit(f"error: {before} and {after}: {e}") from None
        every.extend(cells)
        print(f"## {before} -> {after}\n\n{comparison_table(cells, resamples=args.resamples)}\n")
    if len(args.before) > 1:
        print(f"## all folders\n\n{comparison_table([merge(every, ('all', 0, ''))], resamples=args.resamples)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
