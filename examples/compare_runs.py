"""Two settings on the same problems, run by run: arrivals gained and lost, and the paired cost change.

Give the evaluation folders of each setting (``safe-mapf evaluate --out ...``, one per apartment,
in the same order); each folder's ``runs.csv`` is paired with its counterpart problem by problem
(``baselines.compare``). Prints one table per pair of folders and, for several, one over all.

    python examples/compare_runs.py --before base/apt0 base/apt1 --after new/apt0 new/apt1 --methods ours

With ``--between A B`` it pairs method B's runs with method A's in each folder of ``--before``
instead (``baselines.compare.pair_methods``): "after - before" is then B's largest cost minus A's
on the problems both arrived at, and "lost" / "gained" the problems only A / only B arrived at.

    python examples/compare_runs.py --between sorb ours --before examples/table2/heldout_s4/apt3
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Dict, List

from baselines.compare import comparison_table, merge, pair_methods, pair_runs
from baselines.output import read_rows


def runs_of(folder: Path) -> List[Dict[str, Any]]:
    path = folder / "runs.csv"
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist (run safe-mapf evaluate --out {folder} first)")
    return read_rows(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", nargs="+", type=Path, required=True, help="evaluation folders of the first setting")
    p.add_argument("--after", nargs="+", type=Path, default=None, help="the same problems under the second")
    p.add_argument("--methods", nargs="+", default=None, help="only these methods (default: all)")
    p.add_argument("--between", nargs=2, default=None, metavar=("A", "B"),
                   help="pair method B's runs with method A's in each folder of --before (no --after)")
    p.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples of the paired differences")
    args = p.parse_args(argv)
    if args.between is not None:
        if args.after is not None or args.methods is not None:
            p.error("--between compares two methods within the --before folders: give no --after or --methods")
        args.after = args.before
    elif args.after is None:
        p.error("--after is required (or --between A B to compare two methods within the folders)")
    if len(args.before) != len(args.after):
        p.error(f"{len(args.before)} folders before but {len(args.after)} after: give one of each per evaluation")
    if args.resamples < 1:
        p.error(f"--resamples must be >= 1, got {args.resamples}")
    every = []
    for before, after in zip(args.before, args.after):
        try:
            if args.between is not None:
                cells = pair_methods(runs_of(before), *args.between)
            else:
                cells = pair_runs(*[[r for r in runs_of(f) if args.methods is None or r["method"] in args.methods]
                                    for f in (before, after)])
        except ValueError as e:
            raise SystemExit(f"error: {before} and {after}: {e}") from None
        every.extend(cells)
        title = f"{before}: {args.between[1]} - {args.between[0]}" if args.between else f"{before} -> {after}"
        print(f"## {title}\n\n{comparison_table(cells, resamples=args.resamples)}\n")
    if len(args.before) > 1:
        print(f"## all folders\n\n{comparison_table([merge(every, ('all', 0, ''))], resamples=args.resamples)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
