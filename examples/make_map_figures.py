"""Write a top-down picture of every registered 2D map (default: to ``figures_out/maps/``).

    python examples/make_map_figures.py                    # figures_out/maps/
    python examples/make_map_figures.py --refresh-readme   # examples/figures/maps/, the README's
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import gymnasium as gym

import safe_mapf_envs
from baselines.output import add_figure_output_arguments, figure_output_dir


def main(out_dir: Path) -> None:
    """One 192 x 192 PNG per 2D map in ``out_dir`` (the env's first seeded reset drawn)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for spec in safe_mapf_envs.ENV_SPECS:
        if spec.obs_type != "vector":
            continue
        env = gym.make(spec.id, render_mode="rgb_array")
        env.reset(seed=0)
        img = env.render()
        img = cv2.resize(img, (192, 192), interpolation=cv2.INTER_AREA)
        path = out_dir / f"{spec.layout}.png"
        cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        print(path)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_figure_output_arguments(parser)
    args = parser.parse_args()
    main(figure_output_dir(args, Path(__file__).parent / "figures") / "maps")
