"""Write a square MovingAI ``.map`` file with blocked cells scattered at random.

The large map of the many-agent benchmarks, ``examples/data/maps/scatter-64-64.map``, is::

    python examples/make_scatter_map.py --size 64 --density 0.1 --seed 0 --out examples/data/maps/scatter-64-64.map

Cells are blocked independently with probability ``--density`` (seeded); free cells that the
largest 4-connected free region does not reach are blocked too, so every free cell reaches every
other. Load it with ``GridMap.from_movingai`` (resize factor 3: a 192 x 192 world).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from safe_mapf_envs.maps import GridMap


def scatter_grid(size: int, density: float, seed: int) -> np.ndarray:
    """A ``size x size`` boolean grid (``True`` = blocked) with every free cell in one 4-connected region."""
    if size < 2:
        raise ValueError(f"--size must be at least 2, got {size}")
    if not 0.0 <= density < 1.0:
        raise ValueError(f"--density must be in [0, 1), got {density}")
    blocked = np.random.default_rng(seed).random((size, size)) < density
    return GridMap.from_array(blocked, "scatter").grid


def movingai_text(blocked: np.ndarray) -> str:
    """``blocked`` in the MovingAI ``.map`` format (``@`` blocked, ``.`` free)."""
    h, w = blocked.shape
    rows = ["".join("@" if b else "." for b in row) for row in blocked]
    return "\n".join(["type octile", f"height {h}", f"width {w}", "map", *rows]) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=64, help="cells per side (default 64)")
    p.add_argument("--density", type=float, default=0.1, help="share of cells blocked at random (default 0.1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draw (default 0)")
    p.add_argument("--out", required=True, help="the .map file to write")
    args = p.parse_args()
    grid = scatter_grid(args.size, args.density, args.seed)
    out = Path(args.out)
    out.write_text(movingai_text(grid))
    print(f"wrote {out}: {args.size} x {args.size}, {int(grid.sum())} blocked cells, {int((~grid).sum())} free")


if __name__ == "__main__":
    main()
