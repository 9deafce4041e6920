"""The Figure 1 analogue, and executions as animations.

:func:`trajectory_figure` runs every method on the same problems (one row per agent count)
and draws, per method, the executed trajectories, the planned waypoints, starts (circles) and
goals (stars) over the map's cost field, with each run's largest cumulative cost in the panel
title. :func:`run_animation` writes a GIF of one multi-agent execution: top-down over the cost
field, with trails, planned waypoints and goals.
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np

from .evaluation import EvaluationSetup, make_problems
from .methods import Method, execute

#: One legend for the trajectory figure and the execution frames (the environments' renderer):
#: the same marker means the same thing in both.
MARKER_LEGEND = "lines: trajectories, diamonds: planned waypoints, x: goals"


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
    agent_counts: Sequence[int] = (1, 4),
    difficulty: str = "hard",
    seed: int = 0,
    problems: Optional[Sequence[int]] = None,
    max_cycles: int = 300,
    dpi: int = 110,
) -> Path:
    """Write a PNG with one row per agent count and one column per method; returns its path.

    ``problems`` picks the problem index per row (default: the first problem of each).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problems = [0] * len(agent_counts) if problems is None else list(problems)
    if len(problems) != len(agent_counts):
        raise ValueError(f"{len(agent_counts)} agent counts but {len(problems)} problem indices")
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
                if wp and len(wp[i]):  # the markers of the rendered frames and GIFs (see MARKER_LEGEND)
                    ax.plot(wp[i][:, 0], wp[i][:, 1], "D", color=col, mfc="none", ms=4, mew=1.0)
                ax.plot(*prob.starts[i], "o", color=col, ms=6, mec="k")
                ax.plot(*prob.goals[i], "x", color=col, ms=9, mew=2.2)
            ok = "" if ex.success else ", failed"
            ax.set_title(f"{m.label}\nN={prob.n_agents}: max cost {ex.cost.max():.1f}{ok}", fontsize=8)
            ax.set_xlim(0, w)
            ax.set_ylim(0, h)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_aspect("equal")
    import textwrap

    title = f"{setup.env_id}, {difficulty} problems over the cost field; {MARKER_LEGEND}, discs: starts"
    fig.suptitle(textwrap.fill(title, width=max(40, int(22 * len(methods)))), fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def caption(image: np.ndarray, lines: Sequence[str], scale: float = 0.45) -> np.ndarray:
    """``image`` (RGB) with a white band on top holding ``lines`` of text."""
    import textwrap

    import cv2

    width = max(20, int(image.shape[1] / (18 * scale)))  # characters that fit on a line
    lines = [part for line in lines for part in (textwrap.wrap(line, width) or [""])]
    h_line = int(22 * scale / 0.45)
    band = np.full((h_line * len(lines) + 6, image.shape[1], 3), 255, np.uint8)
    for i, text in enumerate(lines):
        cv2.putText(band, text, (6, h_line * (i + 1)), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([band, image], axis=0)


def execution_frames(field, trajectories: np.ndarray, goals: np.ndarray, goal_threshold: float,
                     waypoints: Optional[Sequence[np.ndarray]] = None, every: int = 1, image_size: int = 480,
                     title: str = "") -> List[np.ndarray]:
    """Top-down RGB frames of an execution: ``trajectories`` ``(T + 1, K, 2)``, goals ``(K, 2)``.

    Agents are discs (with a thick ring once arrived), goals crosses, trails lines in the
    agent's colour and planned waypoints small diamonds on a thin route.
    """
    from safe_mapf_envs.rendering import TopDownRenderer

    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    renderer = TopDownRenderer(field, image_size=image_size)
    traj = np.asarray(trajectories, dtype=np.float64)
    at_goal = np.linalg.norm(traj - np.asarray(goals)[None], axis=-1) <= goal_threshold
    arrived = np.maximum.accumulate(at_goal, axis=0)
    steps = list(range(0, len(traj), every))
    if steps[-1] != len(traj) - 1:
        steps.append(len(traj) - 1)
    frames = []
    for t in steps:
        img = renderer.render(traj[t], goals=goals, trails=[traj[:t + 1, i] for i in range(traj.shape[1])],
                              waypoints=waypoints, parked=arrived[t])
        img = np.ascontiguousarray(img[::-1])  # y up, as in the trajectory figure
        done = int(arrived[t].sum())
        frames.append(caption(img, [title, f"step {t}: {done}/{traj.shape[1]} agents arrived; {MARKER_LEGEND}, "
                                           "discs: agents"]))
    return frames


def write_gif(frames: Sequence[np.ndarray], path, fps: float = 12.0, colors: int = 64) -> Path:
    """Write RGB ``frames`` as a looping GIF (Pillow, which matplotlib installs), each frame with an
    adaptive palette of ``colors`` colours (the cost field's gradients need few; 64 instead of 256
    makes a 10-agent apartment run 1.3 MB instead of 3.3 MB)."""
    from PIL import Image

    if not len(frames):
        raise ValueError("no frames to write")
    if not 2 <= colors <= 256:
        raise ValueError(f"colors must be in [2, 256], got {colors!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)).quantize(colors=colors, method=Image.Quantize.MEDIANCUT)
              for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0,
                   optimize=True)
    return path


def run_animation(setup: EvaluationSetup, method: Method, path, n_agents: int = 5, difficulty: str = "hard",
                  seed: int = 0, problem: int = 0, max_cycles: int = 300, every: int = 2,
                  fps: float = 12.0) -> Path:
    """Run ``method`` on one problem of the evaluation protocol and write the execution as a GIF."""
    import safe_mapf_envs

    prob, field, runs = _runs(setup, [method], n_agents, difficulty, seed, problem, max_cycles)
    _, ex, wp = runs[0]
    env = safe_mapf_envs.parallel_env(setup.env_id, n_agents=n_agents)
    threshold = float(env.goal_threshold)
    env.close()
    agents = f"{n_agents} agent{'s' if n_agents != 1 else ''}"
    outcome = "all arrived" if ex.success else f"{int(ex.reached.sum())}/{n_agents} arrived"
    contacts = f", {ex.collisions} contact{'s' if ex.collisions != 1 else ''} between agents" if n_agents > 1 else ""
    title = (f"{setup.env_id}, {method.label}, {agents} ({difficulty}): {outcome}, "
             f"max cost {ex.cost.max():.1f}{contacts}")
    frames = execution_frames(field, ex.trajectories, prob.goals, threshold, waypoints=wp or None, every=every,
                              title=title)
    return write_gif(frames, path, fps=fps)


__all__ = ["MARKER_LEGEND", "caption", "execution_frames", "run_animation", "trajectory_figure", "write_gif"]
