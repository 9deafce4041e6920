"""The main job (``make demo``): a small version of the paper's 2D evaluation.

With the shipped checkpoints, SoRB + CBS and our constrained search + CBS run the same
5-agent problems on ``SafeCentralObstacle-v0`` (10 per difficulty). The script prints the
table (largest cumulative cost over agents, mean +- std over successful runs, success rate)
and writes ``demo_out/`` (runs.csv, table.csv, table.md, figure.png with every method's
trajectories over the cost field), replacing what an earlier demo wrote there (``--overwrite``).
A few minutes at most on a 2-core CPU.

The full table: ``safe-mapf evaluate --env SafeCentralObstacle-v0 --agents 1 5 10 20 --problems 50``.
"""
from __future__ import annotations

import sys

from baselines.cli import main

if __name__ == "__main__":
    sys.exit(main(["evaluate", "--env", "SafeCentralObstacle-v0", "--agents", "5", "--problems", "10",
                   "--methods", "sorb", "ours", "--out", "demo_out", "--overwrite", *sys.argv[1:]]))
