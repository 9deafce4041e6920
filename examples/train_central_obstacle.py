"""Train the goal-conditioned safe agent on SafeCentralObstacle-v0, both stages.

    python examples/train_central_obstacle.py [--out runs/central] [--seed 0]

Stage 1 trains an unconstrained agent from scratch with the paper's self-sampling: its
critics choose practice problems at predicted distances of 2-15 steps. Its distance and cost
critics are what a planner uses to build its graph.

Stage 2 fine-tunes a copy into the constrained (safe) agent: half of its practice problems
are chosen for a high predicted cost, and the Lagrange multiplier (initial value 0, learning
rate 0.035, capped at 2) grows while episodes cost more than the limit, trading steps for
safety in the actor's objective ``(distance + lambda * cost) / (1 + lambda)``. The limit is
5 here rather than the library default of 10: on this map nearly every training episode
stays under 10, so lambda would fall back towards 0 and the agent would hardly change.

Each stage writes model.zip, config.json, evaluations.jsonl and summary.json to its folder,
and the same runs are available as ``safe-mapf train`` commands (see agents/pretrained/README.md).
On 2 CPU cores each stage takes a few minutes.
"""
from __future__ import annotations

import argparse
import os

from agents.training import TrainConfig, train_stage


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="runs/central", help="parent folder of the two stages")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timesteps", type=int, default=30_000, help="environment steps per stage")
    args = p.parse_args()

    unconstrained = TrainConfig(
        env_id="SafeCentralObstacle-v0", stage="unconstrained", timesteps=args.timesteps, seed=args.seed,
        sampler="self", target_distance=(2.0, 15.0), out_dir=os.path.join(args.out, "unconstrained"),
    )
    first = train_stage(unconstrained)
    print("unconstrained:", first["final_evaluation"], f"({first['wall_s']} s)")

    constrained = TrainConfig(
        env_id="SafeCentralObstacle-v0", stage="constrained", timesteps=args.timesteps, seed=args.seed,
        init=first["model"], sampler="self", target_distance=(2.0, 15.0), target_cost=(10.0, 40.0),
        cost_fraction=0.5, cost_limit=5.0, lagrange_lr=0.035, lagrange_max=2.0, actor_learning_rate=1e-4,
        out_dir=os.path.join(args.out, "constrained"),
    )
    second = train_stage(constrained)
    print("constrained:", second["final_evaluation"], f"({second['wall_s']} s)")


if __name__ == "__main__":
    main()
