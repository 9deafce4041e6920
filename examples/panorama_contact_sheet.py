"""Write a contact sheet of a visual navigation episode: the plan view with the trajectory, and
the RGB-D panoramas the agent sees along it.

The agent is driven by a scripted controller that descends the ground-truth geodesic distance
to the goal (for illustration only: learned agents see the images alone).

Run: ``python examples/panorama_contact_sheet.py [--env SafeApartment0-v0] [--out DIR | --refresh-readme]``
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import List, Tuple

import cv2
import gymnasium as gym
import numpy as np

import safe_mapf_envs
from baselines.output import add_figure_output_arguments, figure_output_dir
from safe_mapf_envs.sensors import VIEW_NAMES, scene_for_layout


@dataclass
class Settings:
    """What to run and where to write it."""

    env: str = "SafeApartment0-v0"
    """a registered visual id"""
    start: Tuple[float, float] = (11.2, 3.8)
    """start position (world units)"""
    goal: Tuple[float, float] = (0.9, 7.6)
    """goal position (world units)"""
    frames: int = 7
    """panoramas shown along the trajectory"""
    max_steps: int = 120
    """step limit of the scripted episode"""
    out: Path = Path("figures_out") / "panorama_contact_sheet.png"
    """PNG to write"""


def scripted_rollout(env, start, goal, max_steps: int) -> Tuple[List[np.ndarray], List[np.ndarray], np.ndarray]:
    """Greedy descent of the geodesic distance to the goal; returns observations, positions, goal view."""
    u = env.unwrapped
    oracle = u.scenario.oracle
    field = oracle.distances_from_cell(int(oracle.cell_of(np.asarray(goal))))  # distances to the goal
    angles = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], 1)
    obs, info = env.reset(options={"start": start, "goal": goal})
    observations, positions = [obs["observation"]], [info["position"]]
    for _ in range(max_steps):
        p = info["position"]
        cand = p + dirs * u.action_scale
        free = u.scenario.is_free(cand)
        score = np.where(free, field[oracle.cell_of(cand)] + np.linalg.norm(cand - goal, axis=1) * 1e-3, np.inf)
        action = dirs[int(np.argmin(score))]
        if np.linalg.norm(goal - p) < u.action_scale:
            action = (goal - p) / u.action_scale
        obs, _, terminated, truncated, info = env.step(action.astype(np.float32))
        observations.append(obs["observation"])
        positions.append(info["position"])
        if terminated or truncated:
            break
    return observations, positions, obs["desired_goal"]


def panorama_strip(pano: np.ndarray, scale: int) -> np.ndarray:
    """The four views side by side in RGB, with their depth below at half height."""
    s = pano.shape[1] * scale
    gap = np.full((s + s // 2, 3, 3), 255, np.uint8)
    tiles = []
    for v in range(4):
        rgb = cv2.resize(pano[v, :, :, :3], (s, s), interpolation=cv2.INTER_NEAREST)
        depth = cv2.resize(pano[v, :, :, 3], (s, s // 2), interpolation=cv2.INTER_NEAREST)
        near = (255.0 * (1.0 - depth / 255.0) ** 2).astype(np.uint8)  # near = light, squared for contrast
        depth = cv2.applyColorMap(near, cv2.COLORMAP_BONE)[..., ::-1]
        tiles += [np.concatenate([rgb, depth], 0), gap]
    return np.concatenate(tiles[:-1], 1)


def label(img: np.ndarray, text: str, org, scale: float = 0.5, colour=(20, 20, 20), thick: int = 1) -> None:
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)


def contact_sheet(cfg: Settings) -> np.ndarray:
    env = gym.make(cfg.env, max_episode_steps=cfg.max_steps)
    observations, positions, goal_view = scripted_rollout(env, np.array(cfg.start), np.array(cfg.goal), cfg.max_steps)
    u = env.unwrapped
    scene = scene_for_layout(u.scenario.layout)
    w, h = scene.size
    ppu = 880.0 / max(w, h)
    plan = scene.top_down(ppu)
    traj = np.array(positions)
    picks = np.unique(np.linspace(0, len(traj) - 1, cfg.frames).round().astype(int))

    def px(p):
        return int(round(p[0] * ppu)), int(round(p[1] * ppu))

    cv2.polylines(plan, [np.array([px(p) for p in traj], np.int32)], False, (255, 255, 255), 6, cv2.LINE_AA)
    cv2.polylines(plan, [np.array([px(p) for p in traj], np.int32)], False, (31, 119, 180), 3, cv2.LINE_AA)
    r = max(4, int(u.scenario.agent_radius * ppu))
    g = px(cfg.goal)
    cv2.drawMarker(plan, g, (255, 255, 255), cv2.MARKER_TILTED_CROSS, 4 * r, 7, cv2.LINE_AA)
    cv2.drawMarker(plan, g, (214, 39, 40), cv2.MARKER_TILTED_CROSS, 4 * r, 3, cv2.LINE_AA)
    for k, i in enumerate(picks):
        c = px(traj[i])
        cv2.circle(plan, c, r + 4, (255, 255, 255), -1, cv2.LINE_AA)
        cv2.circle(plan, c, r + 4, (31, 119, 180), 2, cv2.LINE_AA)
        label(plan, chr(ord("A") + k), (c[0] - 5, c[1] + 5), 0.45, (31, 119, 180), 2)
    plan = np.pad(plan, ((40, 10), (10, 10), (0, 0)), constant_values=255)
    label(plan, f"{cfg.env}: plan view (not seen by the agent), {len(traj) - 1} steps", (10, 26), 0.6)

    x = plan.shape[1] - 24
    cv2.arrowedLine(plan, (x, 34), (x, 12), (20, 20, 20), 2, cv2.LINE_AA, tipLength=0.4)
    label(plan, "N", (plan.shape[1] - 44, 30), 0.5)
    caption = np.full((60, plan.shape[1], 3), 255, np.uint8)
    label(caption, "A, B, ...: where the panoramas on the right were taken; X: the goal.", (10, 22), 0.5, (90, 90, 90))
    label(caption, "Scripted controller descending the ground-truth geodesic distance (illustration only).",
          (10, 46), 0.5, (90, 90, 90))
    plan = np.concatenate([plan, caption], 0)

    scale = 3
    strips = [("goal", goal_view)] + [(f"{chr(ord('A') + k)}: step {i}", observations[i]) for k, i in enumerate(picks)]
    tiles = []
    for name, pano in strips:
        strip = panorama_strip(pano, scale)
        head = np.full((24, strip.shape[1], 3), 255, np.uint8)
        label(head, name, (2, 17), 0.55, (214, 39, 40) if name == "goal" else (31, 119, 180), 2)
        tiles.append(np.concatenate([head, strip, np.full((12, strip.shape[1], 3), 255, np.uint8)], 0))
    if len(tiles) % 2:
        tiles.append(np.full_like(tiles[0], 255))
    gap = np.full((tiles[0].shape[0], 16, 3), 255, np.uint8)
    s = goal_view.shape[1] * scale
    names = np.full((20, tiles[0].shape[1], 3), 255, np.uint8)
    for v, view in enumerate(VIEW_NAMES):
        (tw, _), _ = cv2.getTextSize(view, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        label(names, view, (v * (s + 3) + (s - tw) // 2, 14), 0.5, (90, 90, 90))
    rows = [np.concatenate([names, gap[:20], names], 1)]
    rows += [np.concatenate([tiles[i], gap, tiles[i + 1]], 1) for i in range(0, len(tiles), 2)]
    right = np.pad(np.concatenate(rows, 0), ((40, 10), (10, 10), (0, 0)), constant_values=255)
    label(right, "What the agent sees: RGB-D panoramas, 4 views of 32 x 32 (depth below, near = light)", (10, 26), 0.6)
    height = max(plan.shape[0], right.shape[0])
    plan = np.pad(plan, ((0, height - plan.shape[0]), (0, 0), (0, 0)), constant_values=255)
    right = np.pad(right, ((0, height - right.shape[0]), (0, 0), (0, 0)), constant_values=255)
    return np.concatenate([plan, right], 1)


def main() -> None:
    cfg = Settings()
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default=cfg.env)
    p.add_argument("--start", type=float, nargs=2, default=cfg.start)
    p.add_argument("--goal", type=float, nargs=2, default=cfg.goal)
    p.add_argument("--frames", type=int, default=cfg.frames)
    add_figure_output_arguments(p)
    args = p.parse_args()
    out = figure_output_dir(args, Path(__file__).parent / "figures") / cfg.out.name
    cfg = Settings(env=args.env, start=tuple(args.start), goal=tuple(args.goal), frames=args.frames, out=out)
    if args.env not in {s.id for s in safe_mapf_envs.ENV_SPECS if s.obs_type == "panorama"}:
        raise ValueError(f"--env must be a registered visual id, got {args.env!r}")
    img = contact_sheet(cfg)
    cv2.imwrite(str(cfg.out), cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(cfg.out)


if __name__ == "__main__":
    main()
