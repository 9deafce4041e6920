"""Table I on CenterDot: the paper's numbers, ours under the paper's conventions, ours under the strict protocol.

    safe-mapf evaluate --protocol paper --env SafeCenterDot-v0 --agents 1 5 10 20 --problems 50 \\
        --policies-at 1 --out examples/table1/centerdot_paper
    safe-mapf evaluate --env SafeCenterDot-v0 --agents 1 5 10 20 --problems 50 --policies-at 1 \\
        --methods unconstrained_policy sorb constrained_policy ours --c-max auto --no-figure \\
        --out examples/table1/centerdot_strict
    python examples/centerdot_table.py examples/table1/centerdot_paper examples/table1/centerdot_strict

Each cell of the printed Markdown table holds three lines, each the largest cumulative cost over
agents (mean ± std over successful runs) and the success rate: the paper's Table I, ours under
the paper's conventions (``--protocol paper``; c_max per cell chosen on the test problems, as
the published code does) and ours under the strict protocol (c_max chosen on validation
problems). Below it, for SoRB + CBS and ours, whether our paper-convention mean lies within the
paper's mean ± std, and the strict protocol's verdict: ours cheaper than SoRB + CBS in every
multi-agent cell where ours succeeds in at least 95% of the runs.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from baselines.methods import METHODS
from baselines.metrics import aggregate
from baselines.paper_tables import TABLE1, TABLE1_METHODS


def run_files(folder: Path) -> List[Path]:
    """The ``runs.csv`` of an evaluation folder, or those of its subfolders (one per agent count,
    as an evaluation run one agent count at a time leaves them); ``ValueError`` naming the folder if none."""
    if (folder / "runs.csv").is_file():
        return [folder / "runs.csv"]
    found = sorted(folder.glob("*/runs.csv"))
    if not found:
        raise ValueError(f"{folder}: no runs.csv in it or in its subfolders (the output of safe-mapf evaluate)")
    return found


def load(*folders: Path) -> Dict[Tuple[str, int, str], dict]:
    """Aggregate the rows of ``safe-mapf evaluate`` folders by (difficulty, agents, method). Under
    the paper's protocol only the rows of the c_max chosen per cell are kept."""
    rows: List[dict] = []
    for folder in folders:
        for path in run_files(folder):
            with open(path, newline="") as f:
                rows += list(csv.DictReader(f))
    folder = folders[0]
    if (folder / "c_max.json").exists() and any(r["method"] == "ours" and r["c_max"] != "inf" for r in rows):
        meta = json.loads((folder / "c_max.json").read_text())
        if "chosen_on" in meta:  # the paper's protocol: its best c_max per cell
            chosen = {(c["agents"], c["difficulty"]): float(c["c_max"]) for c in meta["chosen"]}
            rows = [r for r in rows if r["method"] != "ours"
                    or float(r["c_max"]) == chosen[(int(r["agents"]), r["difficulty"])]]
    return {(a["difficulty"], int(a["agents"]), a["method"]): a for a in aggregate(rows)}


def fmt(mean: Optional[float], std: Optional[float], rate: Optional[float]) -> str:
    if rate is None:
        return "n/a"
    if mean is None or math.isnan(mean):
        return f"- ({100 * rate:.0f}%)"
    return f"{mean:.2f} ± {std:.2f} ({100 * rate:.0f}%)"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("paper_folder", type=Path, help="output of safe-mapf evaluate --protocol paper")
    p.add_argument("strict_folders", type=Path, nargs="+",
                   help="output of safe-mapf evaluate (the strict protocol): one folder (its runs.csv, or one "
                        "per subfolder), or one folder per agent count")
    args = p.parse_args()
    try:
        paper_runs, strict = load(args.paper_folder), load(*args.strict_folders)
    except ValueError as exc:
        p.error(str(exc))
    labels = [METHODS[m].label for m in TABLE1_METHODS]
    lines = ["| Problem | Agents | " + " | ".join(labels) + " |", "|---|---|" + "---|" * len(labels)]
    within: List[str] = []
    strict_verdicts: List[str] = []
    for (d, k), paper in sorted(TABLE1.items(), key=lambda x: (["easy", "medium", "hard"].index(x[0][0]), x[0][1])):
        cells = []
        for m, ref in zip(TABLE1_METHODS, paper):
            ours_p, ours_s = paper_runs.get((d, k, m)), strict.get((d, k, m))
            parts = [fmt(*ref) if ref else "n/a"]
            for r in (ours_p, ours_s):
                parts.append(fmt(r["cost_mean"], r["cost_std"], r["success_rate"]) if r else "n/a")
            cells.append("<br>".join(parts))
            if ref and ours_p and m in ("sorb", "ours") and not math.isnan(ours_p["cost_mean"]):
                lo, hi = ref[0] - ref[1], ref[0] + ref[1]
                inside = lo <= ours_p["cost_mean"] <= hi
                within.append(f"{d} {k} {m}: {ours_p['cost_mean']:.2f} vs {ref[0]:.2f} ± {ref[1]:.2f} "
                              f"{'within' if inside else 'OUTSIDE'}")
        lines.append(f"| {d.capitalize()} | {k} | " + " | ".join(cells) + " |")
        s, o = strict.get((d, k, "sorb")), strict.get((d, k, "ours"))
        if k > 1 and s and o and o["success_rate"] >= 0.95:
            cheaper = math.isnan(s["cost_mean"]) or o["cost_mean"] < s["cost_mean"]
            strict_verdicts.append(f"{d} {k}: ours {o['cost_mean']:.2f} vs SoRB + CBS {s['cost_mean']:.2f} "
                                   f"{'cheaper' if cheaper else 'NOT cheaper'}")
    print("Per cell: the paper's Table I / ours, the paper's conventions / ours, the strict protocol\n")
    print("\n".join(lines))
    n_in = sum(" within" in w for w in within)
    print(f"\nPaper's conventions: our mean within the paper's mean ± std in {n_in} of {len(within)} "
          "SoRB + CBS and ours cells")
    for w in within:
        print("  " + w)
    n_ok = sum("NOT" not in v for v in strict_verdicts)
    print(f"\nStrict protocol: ours cheaper than SoRB + CBS in {n_ok} of {len(strict_verdicts)} multi-agent cells "
          "where ours succeeds in at least 95% of the runs")
    for v in strict_verdicts:
        print("  " + v)


if __name__ == "__main__":
    main()
