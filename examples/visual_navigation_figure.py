"""Figures of visual navigation with the learned agents (the paper's Figures 3 and 2, analogues).

    python examples/visual_navigation_figure.py                       # SafeApartment0-v0
    python examples/visual_navigation_figure.py --env SafeApartment2-v0 --difficulty hard

Ours runs as in the Table II runs: its cost cut-off is the one chosen on validation problems
(``examples/table2/apt<k>/c_max.json`` where it exists, for 1 and 4 agents the entries for 1 and
5; ``--c-max`` overrides) and a leg on which the constrained policy is stuck is handed to the
unconstrained one (``--no-fallback`` turns that off).

Writes two PNGs to ``--out`` (default ``figures_out/``; ``--refresh-readme``: ``examples/figures/``,
the README's):

- ``visual_navigation.png``: one agent planned and driven by our method (constrained search on
  the buffer graph of panoramas): the plan view with the executed path and the waypoints over
  the cost field, the panoramas of the start, the goal and each waypoint (what the planner and
  the controller work with), and a few of the panoramas the agent saw on the way. The plan
  view is for the reader: the agent and the planner see panoramas only.
- ``visual_multi_agent.png``: four agents on one problem, SoRB + CBS beside ours.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Dict, Optional

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from panorama_contact_sheet import panorama_strip  # noqa: E402

from agents import load_pretrained  # noqa: E402
from baselines.evaluation import EvaluationSetup, make_problems  # noqa: E402
from baselines.figures import trajectory_figure  # noqa: E402
from baselines.methods import METHODS, Method, execute  # noqa: E402
from baselines.output import add_figure_output_arguments, figure_output_dir  # noqa: E402

HERE = Path(__file__).parent


def chosen_c_max(env_id: str, path: Optional[Path] = None) -> Dict[int, float]:
    """The validation-chosen c_max per agent count of ``env_id``'s Table II folder ({} if none)."""
    if path is None:
        digits = "".join(ch for ch in env_id.split("-")[0] if ch.isdigit())
        path = HERE / "table2" / f"apt{digits}" / "c_max.json"
    if not path.exists():
        return {}
    return {int(k): float(v) for k, v in json.loads(path.read_text())["chosen"].items()}


def ours_method(c_max: Optional[float], fallback: bool) -> Method:
    m = METHODS["ours"]
    if c_max is not None:
        m = m.with_options(c_max=c_max)
    return m.with_options(fallback="unconstrained") if fallback else m


def pick_problem(setup: EvaluationSetup, difficulty: str, seed: int, ours: Method, tries: int = 20):
    """The first single-agent problem on which ours plans through at least two waypoints."""
    import safe_mapf_envs as sme

    env = sme.parallel_env(setup.env_id, n_agents=1, max_cycles=300)
    best = None
    for prob in make_problems(setup, difficulty, 1, tries, seed=seed):
        ex = execute(env, ours, setup.models, setup.planner, prob.starts, prob.goals, seed=seed)
        n_wp = len(ex.extra.get("nodes", [[0]])[0]) - 1
        if ex.success and n_wp >= 2:
            return prob, ex, env
        if best is None and ex.success:
            best = (prob, ex)
    if best is None:
        raise RuntimeError(f"ours reached no {difficulty} goal in {tries} problems: train the agents longer")
    return best[0], best[1], env


def navigation_figure(setup: EvaluationSetup, difficulty: str, seed: int, path: Path, ours: Method,
                      frames: int = 6) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prob, ex, env = pick_problem(setup, difficulty, seed, ours)
    field = env.field
    sensor = env.sensor
    node_ids = np.asarray(ex.extra["nodes"][0][1:], dtype=np.int64)  # waypoints (start node excluded)
    all_obs = np.concatenate([setup.observations, sensor.render(prob.starts), sensor.render(prob.goals)])
    all_pos = np.concatenate([setup.states, prob.starts, prob.goals])
    wp_obs, wp_pos = all_obs[node_ids], all_pos[node_ids]
    traj = ex.trajectories[:, 0]
    steps = np.unique(np.linspace(1, len(traj) - 2, frames).round().astype(int))
    seen = sensor.render(traj[steps])
    strips = ([("start", sensor.render(prob.starts)[0]), ("goal", sensor.render(prob.goals)[0])]
              + [(f"waypoint {i + 1}", o) for i, o in enumerate(wp_obs)]
              + [(f"step {t}", o) for t, o in zip(steps, seen)])
    n_right = len(strips)
    cols = 2
    rows = int(np.ceil(n_right / cols))
    fig = plt.figure(figsize=(15, max(6.0, 1.45 * rows)))
    gs = fig.add_gridspec(rows, 1 + cols, width_ratios=[1.6] + [1.0] * cols)
    ax = fig.add_subplot(gs[:, 0])
    w, h = field.size
    ax.imshow(field.cost_grid(0.05), origin="lower", extent=(0, w, 0, h), cmap="Reds", vmin=0, vmax=2.5)
    for x0, y0, x1, y1 in field.boxes:
        ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, color="0.25"))
    ax.plot(traj[:, 0], traj[:, 1], "-", color="tab:blue", lw=2, label="executed path")
    # the markers of the trajectory figure and the GIFs (baselines.figures.MARKER_LEGEND)
    ax.plot(wp_pos[:, 0], wp_pos[:, 1], "D", color="tab:orange", ms=8, mec="k", label="waypoints")
    for i, p in enumerate(wp_pos):
        ax.annotate(str(i + 1), p, textcoords="offset points", xytext=(6, 6), fontsize=10, weight="bold")
    for t, p in zip(steps, traj[steps]):
        ax.plot(*p, "o", color="white", ms=5, mec="tab:blue")
        ax.annotate(f"t={t}", p, textcoords="offset points", xytext=(4, -12), fontsize=7, color="tab:blue")
    ax.plot(*prob.starts[0], "o", color="tab:green", ms=11, mec="k", label="start")
    ax.plot(*prob.goals[0], "x", color="tab:red", ms=14, mew=3.5, label="goal")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)  # row 0 at the top, as the map and the renderer draw it
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    ax.set_title(f"{setup.env_id}, {difficulty} problem: ours (constrained search + safe policy)\n"
                 f"cumulative cost {ex.cost[0]:.2f}, {ex.steps} steps; plan view not seen by the agent",
                 fontsize=10)
    for k, (name, pano) in enumerate(strips):
        a = fig.add_subplot(gs[k // cols, 1 + k % cols])
        a.imshow(panorama_strip(pano, 2))
        a.set_title(name, fontsize=9, color="tab:blue" if name.startswith("step") else "black")
        a.axis("off")
    fig.suptitle("What the planner and the agent work with: RGB-D panoramas (views N, E, S, W; depth below)",
                 fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    env.close()
    return path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="SafeApartment0-v0")
    p.add_argument("--unconstrained", default=None, help="checkpoint (default: the shipped one)")
    p.add_argument("--constrained", default=None, help="checkpoint (default: the shipped one)")
    p.add_argument("--difficulty", default="medium", choices=["easy", "medium", "hard"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--nodes", type=int, default=1000)
    add_figure_output_arguments(p)
    p.add_argument("--c-max", type=float, default=None,
                   help="ours' cost cut-off (default: examples/table2/apt<k>/c_max.json, else the method's)")
    p.add_argument("--no-fallback", dest="fallback", action="store_false",
                   help="no unconstrained fallback for a stuck leg of ours")
    args = p.parse_args()
    out = figure_output_dir(args, HERE / "figures")
    chosen = chosen_c_max(args.env)
    single = args.c_max if args.c_max is not None else chosen.get(1)
    multi = args.c_max if args.c_max is not None else chosen.get(5)
    torch.set_num_threads(1)
    models = {k: load_pretrained(args.env, k, path=getattr(args, k)) for k in ("unconstrained", "constrained")}
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed, models=models)
    print(navigation_figure(setup, args.difficulty, args.seed, out / "visual_navigation.png",
                            ours_method(single, args.fallback)))
    print(trajectory_figure(setup, [METHODS["sorb"], ours_method(multi, args.fallback)],
                            out / "visual_multi_agent.png",
                            agent_counts=(4,), difficulty=args.difficulty, seed=args.seed, problems=(0,)))


if __name__ == "__main__":
    main()
