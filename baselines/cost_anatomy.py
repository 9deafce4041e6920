"""Cost anatomy: where the largest cumulative cost of a run goes.

Table II compares the largest cumulative safety cost over a run's agents. An agent pays the cost
on every step it spends near an obstacle, moving or not, so a run's largest cost is made by
what its costliest agent did step by step. The controller records that
(``ControllerStats.activity``, one of :data:`~agents.search.execution.stats.ACTIVITIES`): driven by its
policy, by the fallback policy, escaping, or standing still for the plan's times, for an agent the
plan sends first, for its parking, for another agent's goal, or to yield.

:func:`~baselines.methods.execute` splits each agent's cost by activity
(``Execution.cost_split``); a row of ``safe-mapf evaluate`` keeps the costliest agent's split in
its ``cost_split`` field (:func:`cost_split_field`). :func:`cost_anatomy` averages it per
evaluation cell over the successful runs, :func:`cost_anatomy_table` and
:func:`cost_anatomy_figure` show it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Iterable, List, Sequence

import numpy as np

from agents.search.execution.stats import ACTIVITIES

from .output import parse_named_values


def cost_split_field(split: np.ndarray, cost: np.ndarray) -> str:
    """The compact form kept in a run's row: the costliest agent's cost per activity, as
    ``activity=cost`` joined by ``;`` (activities with no cost left out; empty when not recorded)."""
    split = np.asarray(split, dtype=np.float64)
    if split.size == 0 or len(cost) == 0:
        return ""
    row = split[int(np.argmax(cost))]
    return ";".join(f"{a}={v:.2f}" for a, v in zip(ACTIVITIES, row) if v > 0)


def parse_cost_split(text: Any) -> Dict[str, float]:
    """The activities and costs of a row's ``cost_split`` field (see :func:`cost_split_field`)."""
    return parse_named_values(text, ACTIVITIES, float, "cost_split")


def cost_anatomy(rows: Iterable[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per (method, agents, difficulty): over the successful runs that recorded a split, the mean
    largest cost (``cost``) and the mean of its part per activity (one key per activity), with
    ``runs`` the number of runs averaged."""
    cells: Dict[tuple, List[Dict[str, float]]] = {}
    for r in rows:
        success = r["success"] in (True, "True", "true", "1")
        split = parse_cost_split(r.get("cost_split"))
        if success and split:
            cells.setdefault((r["method"], int(r["agents"]), r["difficulty"]), []).append(split)
    order = {"easy": 0, "medium": 1, "hard": 2}
    out = []
    for (m, k, d), splits in sorted(cells.items(), key=lambda c: (c[0][0], c[0][1], order.get(c[0][2], 9))):
        parts = {a: float(np.mean([s.get(a, 0.0) for s in splits])) for a in ACTIVITIES}
        out.append({"method": m, "agents": k, "difficulty": d, "runs": len(splits),
                    "cost": sum(parts.values()), **parts})
    return out


def cost_anatomy_table(summary: Sequence[Dict[str, Any]]) -> str:
    """Markdown: per cell, the mean largest cost and its parts per activity (share in brackets)."""
    head = "| Method | Problem | Agents | runs | largest cost | " + " | ".join(ACTIVITIES) + " |"
    lines = [head, "|" + "---|" * (5 + len(ACTIVITIES))]
    for c in summary:
        parts = [f"{c[a]:.2f} ({c[a] / c['cost']:.0%})" if c[a] > 0 else "0" for a in ACTIVITIES]
        lines.append(f"| {c['method']} | {c['difficulty'].capitalize()} | {c['agents']} | {c['runs']} | "
                     f"{c['cost']:.2f} | " + " | ".join(parts) + " |")
    return "\n".join(lines)


def cost_anatomy_figure(summary: Sequence[Dict[str, Any]], path: Any, title: str = "") -> Path:
    """Stacked bars of the mean largest cost per cell, split by activity; saved to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not summary:
        raise ValueError("no cell with a recorded cost split to draw")
    labels = [f"{c['method']}\n{c['difficulty']}-{c['agents']}" for c in summary]
    x = np.arange(len(summary))
    fig, ax = plt.subplots(figsize=(max(6.0, 0.7 * len(summary) + 2), 4.2))
    bottom = np.zeros(len(summary))
    colours = plt.get_cmap("tab10")
    for j, a in enumerate(ACTIVITIES):
        v = np.array([c[a] for c in summary])
        if v.any():
            ax.bar(x, v, bottom=bottom, label=a, color=colours(j))
        bottom += v
    ax.set_ylim(0, 1.3 * float(bottom.max()) if bottom.max() > 0 else 1.0)  # room for the legend
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("mean largest cumulative cost")
    ax.set_title(title or "Where the costliest agent's cost goes")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


__all__ = ["cost_anatomy", "cost_anatomy_figure", "cost_anatomy_table", "cost_split_field", "parse_cost_split"]
