"""The Figure 1 analogue: each method's trajectories over the cost heat map.

:func:`trajectory_figure` runs every method on one single-agent and one multi-agent problem
(the same problems for all methods) and draws, per method, the executed trajectories, the
planned waypoints, starts (circles) and goals (stars) over the map's cost field, with each
run's largest cumulative cost in the panel title.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence, Tuple

import numpy as np

from .evaluation import EvaluationSetup, make_problems
from .methods import Method, execute


def _runs(setup: EvaluationSetup, methods: Sequence[Method], n_agents: int, difficulty: str, seed: int,
          problem: int, max_cycles: int):
    import safe_mapf_envs

    prob = make_problems(setup, difficulty, n_agents, problem + 1, seed=seed)[problem]
    env = safe_mapf_envs.parallel_env(setup.env_id, n_agents=n_agents, max_cycles=max_cycles)
    field = env.field
    out = []
    for m in methods:
        ex = execute(env, m, setup.models, setup.planner, prob.starts, prob.goals, seed=seed)
        wp = []
        if ex.extra.get("nodes"):
            pos = np.concatenate([setup.states, prob.starts, prob.goals])
            wp = [pos[np.asarray(n[1:], dtype=np.int64)] for n in ex.extra["nodes"]]
        out.append((m, ex, wp))
    env.close()
    return prob, field, out


def trajectory_figure(
    setup: EvaluationSetup,
    methods: Sequence[Method],
    path,
    agent_counts: Tuple[int, int] = (1, 4),
    difficulty: str = "hard",
    seed: int = 0,
    problems: Tuple[int, int] = (0, 0),
    max_cycles: int = 300,
    dpi: int = 110,
) -> Path:
    """Write a PNG with one row per agent count and one column per method; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [_runs(setup, methods, k, difficulty, seed, p, max_cycles) for k, p in zip(agent_counts, problems)]
    field = rows[0][1]
    w, h = field.size
    grid = field.cost_grid(0.25)
    fig, axes = plt.subplots(len(rows), len(methods), figsize=(3.1 * len(methods), 3.2 * len(rows)),
                             squeeze=False)
    colors = plt.get_cmap("tab10")
    for r, (prob, _field, runs) in enumerate(rows):
        for c, (m, ex, wp) in enumerate(runs):
            ax = axes[r, c]
            ax.imshow(grid, origin="lower", extent=(0, w, 0, h), cmap="Reds", vmin=0, vmax=2.5)
            for x0, y0, x1, y1 in field.boxes:
                ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, color="0.2"))
            for i in range(prob.n_agents):
                col = colors(i % 10)
                tr = ex.trajectories[:, i]
                ax.plot(tr[:, 0], tr[:, 1], "-", color=col, lw=1.6)
                if wp and len(wp[i]):
                    ax.plot(wp[i][:, 0], wp[i][:, 1], "x", color=col, ms=4, mew=1.2)
                ax.plot(*prob.starts[i], "o", color=col, ms=6, mec="k")
                ax.plot(*prob.goals[i], "*", color=col, ms=11, mec="k")
            ok = "" if ex.success else ", failed"
            ax.set_title(f"{m.label}\nN={prob.n_agents}: max cost {ex.cost.max():.1f}{ok}", fontsize=8)
            ax.set_xlim(0, w)
            ax.set_ylim(0, h)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_aspect("equal")
    import textwrap

    title = (f"{setup.env_id}, {difficulty} problems: trajectories (lines), waypoints (x), "
             f"starts (o), goals (*) over the cost field")
    fig.suptitle(textwrap.fill(title, width=max(40, int(22 * len(methods)))), fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


__all__ = ["trajectory_figure"]
