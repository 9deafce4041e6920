"""Gradient updates per second of the vector and the panorama agents, old and new layout.

    python examples/bench_training.py                 # torch's default threads and 1 thread
    python examples/bench_training.py --updates 300 --threads 2

One update = one minibatch (64 by default) through 3 distance critics and 3 cost critics
(20 and 40 bins), their targets and the actor, as ``SafeGoalTD3.train`` runs it. Rows:

- vector agent (SafeCentralObstacle-v0): an MLP extractor per network;
- panorama agent (SafeApartment0-v0), the old layout: an extractor per network (six copies of
  the paper's encoder: observation, goal and next observation encoded by each) with a plain
  ``nn.Conv2d`` stack over the full views;
- the same layout with the fast encoder (receptive-field crop, first convolution as one matrix
  product: the same function, see ``agents.encoders.PanoramaEncoder``);
- the new layout: one shared encoder trained by the critic losses, the actor on detached
  features, observation and goal encoded in one pass, the next observation by the target
  encoder only (the default for images);
- the new layout with DrQ's random-shift augmentation;
- the new layout with the full-view encoder (``agents.training.FULL_VIEW_CONV_LAYERS``: the
  paper's layers read only the top-left 20 x 20 pixels of a 32 x 32 view, this one all), and
  with ``(16, 8, 8), (32, 4, 4)`` (every pixel, in non-overlapping 8 x 8 patches).

A last line times the whole training loop (environment step, replay, one update per step) of
the new layout. The replay buffer is filled by a short random run first.
"""
from __future__ import annotations

import argparse
import time
from contextlib import contextmanager
from typing import Dict, Iterator, Optional, Sequence, Tuple

import gymnasium as gym
import torch
from stable_baselines3.common.logger import configure

import safe_mapf_envs  # noqa: F401
from agents import SafeGoalTD3
from agents.encoders import PanoramaEncoder, is_image_space
from agents.training import FULL_VIEW_CONV_LAYERS


@contextmanager
def plain_conv_stack() -> Iterator[None]:
    """Run every PanoramaEncoder as the plain nn.Conv2d stack (the old code path)."""
    fast = PanoramaEncoder.forward
    PanoramaEncoder.forward = PanoramaEncoder.reference_forward
    try:
        yield
    finally:
        PanoramaEncoder.forward = fast


def make_model(env_id: str, share: Optional[bool], augmentation: Optional[str], batch: int,
               conv_layers: Optional[Sequence[Tuple[int, int, int]]] = None) -> SafeGoalTD3:
    env = gym.make(env_id)
    image = is_image_space(env.observation_space["observation"])
    extractor = {} if conv_layers is None else {"conv_layers": list(conv_layers)}
    model = SafeGoalTD3(
        "MultiInputPolicy", env, batch_size=batch, learning_starts=0, seed=0, device="cpu",
        problem_sampler="uniform", augmentation=augmentation,
        replay_buffer_kwargs=dict(achieved_goal_is_observation=image),
        policy_kwargs=dict(net_arch=[64, 64], n_critics=3, n_cost_critics=3, share_encoder=share,
                           features_extractor_kwargs=extractor))
    model.set_logger(configure(None, []))
    model.train = lambda *a, **k: None  # fill the buffer without learning
    model.learn(400)
    del model.train
    return model


def updates_per_second(model: SafeGoalTD3, updates: int, batch: int) -> float:
    model.train(5, batch)  # warm-up
    t = time.perf_counter()
    model.train(updates, batch)
    return updates / (time.perf_counter() - t)


def loop_steps_per_second(model: SafeGoalTD3, steps: int) -> float:
    t = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - t)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--updates", type=int, default=200, help="timed updates per row")
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--threads", type=int, nargs="+", default=None,
                   help="torch thread counts to time (default: torch's default, then 1)")
    p.add_argument("--loop-steps", type=int, default=600, help="steps of the whole-loop timing (0: skip)")
    args = p.parse_args()
    default_threads = torch.get_num_threads()
    threads = args.threads or sorted({default_threads, 1}, reverse=True)

    rows = [
        ("vector, an MLP extractor per network", "SafeCentralObstacle-v0", False, None, False, None),
        ("panorama, old: an extractor per network, plain conv", "SafeApartment0-v0", False, None, True, None),
        ("panorama, an extractor per network, fast encoder", "SafeApartment0-v0", False, None, False, None),
        ("panorama, new: one shared encoder (default)", "SafeApartment0-v0", True, None, False, None),
        ("panorama, new + random shift", "SafeApartment0-v0", True, "shift", False, None),
        ("panorama, new + full-view encoder", "SafeApartment0-v0", True, None, False, FULL_VIEW_CONV_LAYERS),
        ("panorama, new + full view, 8 x 8 patches", "SafeApartment0-v0", True, None, False, ((16, 8, 8), (32, 4, 4))),
    ]
    print(f"gradient updates/s, batch {args.batch}, 3 + 3 critics, heads 64-64 "
          f"({args.updates} timed updates per row; torch default threads here: {default_threads})")
    results: Dict[int, Dict[str, float]] = {}
    for n in threads:
        torch.set_num_threads(n)
        results[n] = {}
        for label, env_id, share, aug, plain, conv in rows:
            model = make_model(env_id, share, aug, args.batch, conv)
            if plain:
                with plain_conv_stack():
                    ups = updates_per_second(model, args.updates, args.batch)
            else:
                ups = updates_per_second(model, args.updates, args.batch)
            results[n][label] = ups
            print(f"  threads={n}  {label:55s} {ups:7.1f} updates/s", flush=True)
        old = results[n][rows[1][0]]
        new = results[n][rows[3][0]]
        print(f"  threads={n}  panorama speed-up, new vs old layout: {new / old:.1f}x  "
              f"[{'PASS' if new >= 50 else 'FAIL'} >= 50 updates/s]")
        if args.loop_steps > 0:
            model = make_model("SafeApartment0-v0", True, None, args.batch)
            sps = loop_steps_per_second(model, args.loop_steps)
            print(f"  threads={n}  whole training loop, new layout: {sps:.1f} env steps/s "
                  f"(one update per step)", flush=True)


if __name__ == "__main__":
    main()
