"""``safe-mapf evaluate --protocol paper`` on several cores: one process per cell, merged into one folder.

    for a in 0 1 2 3; do
        python examples/paper_cells.py --env SafeApartment$a-v0 --agents 1 5 10 --problems 50 \\
            --workers 2 --out examples/table2/paper/apt$a
    done

``safe-mapf evaluate --protocol paper --ray`` runs the runs on several cores in one process; this
script runs whole cells apart instead, and can be resumed. The cells are independent:
each (agent count, difficulty) draws its problems from the seed alone, every run is seeded with
the seed plus the problem's index, and ours' c_max is chosen per cell. So the cells can run as
separate ``safe-mapf evaluate --protocol paper`` processes (``--workers`` at a time, the longest
first, each with one torch thread) and their rows, put together in the order of a single run,
are the rows that one command over all cells would write. The merged folder holds ``runs.csv``,
``table.md``, ``table.csv``, ``table.json`` and ``c_max.json`` as that command writes them; the
cells' own folders and logs are under ``OUT/cells`` and are removed after the merge unless
``--keep-cells``. A cell whose folder already holds a finished run (its ``table.md``) is not
run again, so an interrupted call continues where it stopped.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import List, Tuple

from baselines.evaluation import DIFFICULTIES
from baselines.output import RowWriter, read_rows
from baselines.paper_protocol import PAPER_PROTOCOL_METHODS, write_paper_outputs

Cell = Tuple[int, str]


def cell_dir(out: Path, cell: Cell) -> Path:
    return out / "cells" / f"{cell[0]}_{cell[1]}"


def run_cell(args: argparse.Namespace, cell: Cell) -> float:
    """Run one cell in its own process; returns its wall time in seconds (``RuntimeError`` if it fails)."""
    folder = cell_dir(args.out, cell)
    cmd = [sys.executable, "-m", "baselines.cli", "evaluate", "--protocol", "paper", "--env", args.env,
           "--agents", str(cell[0]), "--difficulty", cell[1], "--problems", str(args.problems),
           "--seed", str(args.seed), "--nodes", str(args.nodes), "--paper-candidates", str(args.paper_candidates),
           "--methods", *args.methods, "--no-figure", "--no-progress", "--out", str(folder),
           *(["--resume"] if (folder / "run.json").exists() else [])]  # a cell an interruption cut short goes on
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    t0 = time.perf_counter()
    with open(folder.with_suffix(".log"), "w") as log:
        done = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    if done.returncode:
        raise RuntimeError(f"cell {cell} failed (exit {done.returncode}); see {folder.with_suffix('.log')}")
    return time.perf_counter() - t0


def merge(args: argparse.Namespace) -> str:
    """Put the cells' rows together in the order of one run and write the folder's tables (the
    time in ``table.md``'s header is the sum of the cells' times)."""
    rows, settings, seconds = [], [], 0.0
    for k in args.agents:  # the order of one command's rows
        for d in args.difficulty:
            folder = cell_dir(args.out, (k, d))
            rows += read_rows(folder / "runs.csv")
            meta = json.loads((folder / "c_max.json").read_text())
            settings.append((meta["cost_limit"], meta["grid"], meta["targets"]))
            took = re.search(r"seed -?\d+, (\d+) s;", (folder / "table.md").read_text())
            seconds += float(took.group(1)) if took else 0.0
    if any(s != settings[0] for s in settings):
        raise ValueError(f"the cells of {args.out} were run with different agents or maps: {settings}")
    with RowWriter(args.out / "runs.csv") as writer:
        for r in rows:
            writer.write(r)
    cost_limit, grid, targets = settings[0]
    methods = [m for m in args.methods if any(r["method"] == m for r in rows)]
    _, text = write_paper_outputs(rows, args.out, methods, env_id=args.env, n_problems=args.problems, seed=args.seed,
                                  wall=seconds, cost_limit=cost_limit, grid=grid, targets=targets)
    return text


def main(argv: List[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", required=True)
    p.add_argument("--agents", type=int, nargs="+", default=[1, 5, 10])
    p.add_argument("--difficulty", nargs="+", choices=list(DIFFICULTIES), default=list(DIFFICULTIES))
    p.add_argument("--problems", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--nodes", type=int, default=1000)
    p.add_argument("--paper-candidates", type=int, default=200)
    p.add_argument("--methods", nargs="+", default=list(PAPER_PROTOCOL_METHODS))
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="cells run at a time (default: CPUs)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--keep-cells", action="store_true", help="keep each cell's folder and log under OUT/cells")
    args = p.parse_args(argv)
    if args.workers < 1 or args.problems < 1 or min(args.agents) < 1:
        p.error("--workers, --problems and --agents must be at least 1")
    cells = [(k, d) for k in args.agents for d in args.difficulty]
    (args.out / "cells").mkdir(parents=True, exist_ok=True)
    todo = [c for c in cells if not (cell_dir(args.out, c) / "table.md").exists()]
    todo.sort(key=lambda c: (-c[0], -list(DIFFICULTIES).index(c[1])))  # the longest first
    print(f"{args.env}: {len(cells)} cells, {len(cells) - len(todo)} already run, {args.workers} at a time",
          file=sys.stderr, flush=True)
    with ThreadPoolExecutor(args.workers) as pool:
        for cell, seconds in zip(todo, pool.map(lambda c: run_cell(args, c), todo)):
            print(f"  {cell[0]} agents, {cell[1]}: {seconds:.0f} s", file=sys.stderr, flush=True)
    print(merge(args))
    if not args.keep_cells:
        shutil.rmtree(args.out / "cells")
    return 0


if __name__ == "__main__":
    sys.exit(main())
