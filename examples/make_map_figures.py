"""Write a top-down picture of every registered 2D map to ``examples/figures/maps/``.

Run: ``python examples/make_map_figures.py``
"""
from __future__ import annotations

from pathlib import Path

import cv2
import gymnasium as gym

import safe_mapf_envs


def main(out_dir: Path = Path(__file__).parent / "figures" / "maps") -> None:
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
    main()
