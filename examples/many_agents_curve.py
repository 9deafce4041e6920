"""Success against the number of agents, in the metrics the MAPF learning community reads.

Reads the ``runs.csv`` of ``safe-mapf evaluate`` output folders (one per environment, named by
the folder's name), prints one Markdown table per folder and draws one figure: per agent count,
CSR (the share of runs in which every agent arrived), ISR (the mean share of agents arrived),
the sum of costs per agent and the makespan (POGEMA's definitions: an agent that never arrives
counts the run's length), our largest cumulative safety cost over agents, the contacts
between agents and the safety rate (the share of agents that never touched another; means over
all runs), and the median time of the first plan. The figures of ``docs/many_agents.md`` come from::

    safe-mapf evaluate --agents 1 5 10 20 50 100 200 --problems 10 --difficulty hard --methods ours \\
        --no-figure --out examples/many_agents/central_obstacle
    safe-mapf evaluate --env SafeApartment0-v0 --agents 1 5 10 20 30 --problems 5 --difficulty hard \\
        --methods ours --c-max 1.29 --fallback --no-figure --out examples/many_agents/apartment0
    python examples/many_agents_curve.py examples/many_agents/central_obstacle examples/many_agents/apartment0 \\
        --out docs/figures/many_agents.png

Run: ``python examples/many_agents_curve.py FOLDER [FOLDER ...] [--method ours] [--out PNG]``
"""
from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path
from typing import Any, Dict, List

import numpy as np

from baselines.metrics import aggregate


def cells(folder: Path, method: str) -> List[Dict[str, Any]]:
    """The aggregate rows of ``method`` in ``folder/runs.csv`` (every difficulty pooled per agent count)."""
    path = folder / "runs.csv"
    if not path.exists():
        raise SystemExit(f"{path} does not exist: pass folders written by safe-mapf evaluate --out")
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["method"] == method]
    if not rows:
        raise SystemExit(f"{path} has no runs of method {method!r}")
    if "isr" not in rows[0]:
        raise SystemExit(f"{path} has no isr / soc / makespan columns: it was written before they existed")
    for r in rows:
        r["difficulty"] = "all"
    out = aggregate(rows)
    by_agents: Dict[int, List[Dict[str, Any]]] = {}
    for r in rows:
        by_agents.setdefault(int(r["agents"]), []).append(r)
    for a in out:  # means over all runs (aggregate's cost and contacts are over successful runs)
        rs = by_agents[a["agents"]]
        a["cost_all_mean"] = float(np.mean([float(r["cost_max"]) for r in rs]))
        a["contacts_all_mean"] = float(np.mean([float(r["collisions"]) for r in rs]))
        a["safety_rate_all_mean"] = float(np.mean([float(r.get("safety_rate") or "nan") for r in rs]))
        a["planning_time_median"] = float(np.median([float(r["planning_time"]) for r in rs]))
    return sorted(out, key=lambda a: a["agents"])


def markdown(name: str, rows: List[Dict[str, Any]]) -> str:
    head = ["agents", "runs", "CSR", "ISR", "sum of costs / agent", "makespan", "max cumulative cost",
            "contacts", "safety rate", "planning time (median)"]
    lines = [f"{name}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for a in rows:
        k = a["agents"]
        lines.append(f"| {k} | {a['runs']} | {100 * a['csr']:.0f}% | {100 * a['isr']:.1f}% | "
                     f"{a['soc_mean'] / k:.1f} | {a['makespan_mean']:.0f} | {a['cost_all_mean']:.1f} | "
                     f"{a['contacts_all_mean']:.1f} | {_share(a['safety_rate_all_mean'])} | "
                     f"{a['planning_time_median']:.2f} s |")
    return "\n".join(lines)


def _share(x: float) -> str:
    """A share as a percentage; ``n/a`` for rows that did not record it."""
    return "n/a" if math.isnan(x) else f"{100 * x:.1f}%"


def figure(named: Dict[str, List[Dict[str, Any]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(17, 3.8))
    for name, rows in named.items():
        k = np.array([a["agents"] for a in rows])
        line, = axes[0].plot(k, [100 * a["isr"] for a in rows], "o-", label=f"{name}: ISR")
        axes[0].plot(k, [100 * a["csr"] for a in rows], "s--", color=line.get_color(), label=f"{name}: CSR")
        axes[0].plot(k, [100 * a["safety_rate_all_mean"] for a in rows], "^:", color=line.get_color(),
                     label=f"{name}: safety rate")
        axes[1].plot(k, [a["soc_mean"] / a["agents"] for a in rows], "o-", color=line.get_color(),
                     label=f"{name}: sum of costs / agent")
        axes[1].plot(k, [a["makespan_mean"] for a in rows], "s--", color=line.get_color(), label=f"{name}: makespan")
        axes[2].plot(k, [a["cost_all_mean"] for a in rows], "o-", color=line.get_color(),
                     label=f"{name}: max cumulative cost")
        axes[2].plot(k, [a["contacts_all_mean"] for a in rows], "s--", color=line.get_color(),
                     label=f"{name}: contacts")
        axes[3].plot(k, [a["planning_time_median"] for a in rows], "o-", color=line.get_color(),
                     label=f"{name}: first plan")
    titles = ["agents arrived, agents never touched (%)", "steps", "per run (mean)", "planning time (s, median)"]
    ticks = sorted({a["agents"] for rows in named.values() for a in rows})
    for ax, title in zip(axes, titles):
        ax.set_xscale("log")
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel("agents")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylim(0, 105)
    axes[2].set_yscale("symlog", linthresh=1.0)
    axes[2].set_ylim(bottom=0)
    axes[3].set_yscale("log")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", nargs="+", type=Path, help="safe-mapf evaluate output folders")
    p.add_argument("--method", default="ours")
    p.add_argument("--out", type=Path, default=None, help="write the figure here (PNG)")
    args = p.parse_args()
    named = {}
    for folder in args.folders:
        name = folder.name
        named[name] = cells(folder, args.method)
        print(markdown(name, named[name]) + "\n")
    if args.out is not None:
        figure(named, args.out)
        print(f"wrote {args.out}")
    if any(math.isnan(a["soc_mean"]) for rows in named.values() for a in rows):
        print("note: some runs lack sum of costs")


if __name__ == "__main__":
    main()
