"""The Table II analogue: our four apartments, and the paper's four scenes beside them, as Markdown tables.

    for a in 0 1 2 3; do
        safe-mapf evaluate --env SafeApartment$a-v0 --agents 1 5 10 --problems 50 \
            --methods unconstrained_policy sorb constrained_policy ours --policies-at 1 \
            --c-max-from examples/table2/apt$a/c_max.json --fallback --no-figure --ray --out examples/table2/layer/apt$a
    done
    python examples/visual_table.py examples/table2/layer/apt0 examples/table2/layer/apt1 examples/table2/layer/apt2 \
        examples/table2/layer/apt3

(with ``--safety off``, the runs without the safety layer, in ``examples/table2/apt$a``; each
folder's ``c_max.json`` is the choice of an earlier ``--c-max auto --validation-problems 5``
run, made on validation problems drawn with seed 10000). The same table under the paper's
conventions, from folders of ``safe-mapf evaluate --protocol paper`` (or of
``examples/paper_cells.py``), keeps per cell the c_max of ours that the run chose on its test
problems:

    python examples/visual_table.py --protocol paper examples/table2/paper/apt0 examples/table2/paper/apt1 \
        examples/table2/paper/apt2 examples/table2/paper/apt3

Reads each folder's ``runs.csv`` (or ``table.json``; written by ``safe-mapf evaluate``) and prints
two Markdown tables. The first has, per apartment, difficulty and agent count, SoRB + CBS and ours
(largest cumulative cost over agents, mean ± std over successful runs, success rate and, in
multi-agent cells, safety rate), their medians over successful runs, and whether ours is cheaper
than SoRB + CBS in a multi-agent cell where ours succeeds in at least 90% of the runs, by the mean
(the paper's measure) and by the median. The second has the paper's Table II figures for the
scene in the same position. The paper's scenes are other apartments (ReplicaCAD in Habitat): they
give scale, not a like-for-like comparison.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from baselines.evaluation import safety_note
from baselines.metrics import aggregate
from baselines.output import read_rows
from baselines.paper_protocol import choose_best_c_max
from baselines.paper_tables import TABLE2, TABLE2_METHODS, TABLE2_SCENES

#: column names of our methods; other methods are shown by their name
LABELS = {"sorb": "SoRB + CBS", "ours": "ours"}


def fmt(mean, std, rate, note: str = "") -> str:
    """``mean ± std (success%)``, with ``note`` (the safety rate) inside the brackets."""
    if mean is None or (isinstance(mean, float) and math.isnan(mean)):
        return f"- ({100 * rate:.0f}%{note})" if rate is not None else "n/a"
    return f"{mean:.2f} ± {std:.2f} ({100 * rate:.0f}%{note})"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", nargs="+", type=Path, help="safe-mapf evaluate output folders, one per apartment")
    p.add_argument("--methods", nargs="+", default=["sorb", "ours"], help="our methods to show")
    p.add_argument("--protocol", choices=("strict", "paper"), default="strict",
                   help="paper: folders of --protocol paper runs (ours at the c_max each cell chose)")
    args = p.parse_args()
    labels = [LABELS.get(m, m) for m in args.methods]
    head = ["Env", "Problem", "Agents", *labels, "median: " + " / ".join(labels), "ours cheaper: mean / median"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    paper_head = ["Env", "paper: scene", "Problem", "Agents", "paper: SoRB + CBS", "paper: ours"]
    paper_lines = ["| " + " | ".join(paper_head) + " |", "|" + "---|" * len(paper_head)]
    for i, folder in enumerate(args.folders):
        runs = folder / "runs.csv"
        if runs.exists():  # aggregate the runs here, so that every figure of aggregate() is there
            runs_rows = read_rows(runs)
            rows = aggregate(choose_best_c_max(runs_rows)[0] if args.protocol == "paper" else runs_rows)
        else:
            rows = json.loads((folder / "table.json").read_text())
        meta = folder / "table.md"
        env_id = meta.read_text().split(":", 1)[0].split(",")[0] if meta.exists() else folder.name
        cell = {(r["difficulty"], r["agents"], r["method"]): r for r in rows}
        scene = TABLE2_SCENES[i] if i < len(TABLE2_SCENES) else "-"
        keys = sorted({(r["difficulty"], r["agents"]) for r in rows},
                      key=lambda x: (["easy", "medium", "hard"].index(x[0]), x[1]))
        for d, k in keys:
            parts = [env_id, d.capitalize(), str(k)]
            medians = []
            for m in args.methods:
                r = cell.get((d, k, m))
                parts.append(fmt(r["cost_mean"], r["cost_std"], r["success_rate"], safety_note(r)) if r else "n/a")
                median = r.get("cost_median") if r else None
                medians.append("-" if median is None or math.isnan(median) else f"{median:.2f}")
            parts.append(" / ".join(medians))
            s, o = cell.get((d, k, "sorb")), cell.get((d, k, "ours"))
            verdict = ""
            if k > 1 and s and o and o["success_rate"] >= 0.9:
                verdict = "yes" if (math.isnan(s["cost_mean"]) or o["cost_mean"] < s["cost_mean"]) else "**no**"
                if "cost_median" in o and "cost_median" in s:
                    better = math.isnan(s["cost_median"]) or o["cost_median"] < s["cost_median"]
                    verdict += " / " + ("yes" if better else "no")
            parts.append(verdict)
            lines.append("| " + " | ".join(parts) + " |")
            paper = TABLE2.get((scene, d, k))
            paper_parts = [env_id, scene, d.capitalize(), str(k)]
            for m in ("sorb", "ours"):
                c = paper[TABLE2_METHODS.index(m)] if paper else None
                paper_parts.append(fmt(*c) if c else "n/a")
            paper_lines.append("| " + " | ".join(paper_parts) + " |")
    print("\n".join(lines))
    print("\nThe paper's Table II, for the scene in the same position:\n")
    print("\n".join(paper_lines))


if __name__ == "__main__":
    main()
