"""One training stage from a settings object: what ``safe-mapf train`` runs.

The paper trains in two stages: an **unconstrained** goal-conditioned agent (its distance and
cost critics annotate the planner's graph), then a **constrained** agent fine-tuned from it
with a Lagrange multiplier (it follows the planned waypoints safely). :func:`train_stage`
runs one stage from a :class:`TrainConfig` and writes, into ``out_dir``:

- ``model.zip``: the final checkpoint (``checkpoint.zip`` is refreshed at every evaluation);
- ``config.json``: the settings, the command line and the library versions;
- ``evaluations.jsonl``: one line of held-out figures per evaluation;
- ``summary.json``: steps, wall and CPU time, final figures.
"""
from __future__ import annotations

import dataclasses
import json
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

STAGES = ("unconstrained", "constrained")


@dataclass
class TrainConfig:
    """Settings of one training stage."""

    env_id: str = "SafeCentralObstacle-v0"
    """a registered goal-conditioned environment id"""
    stage: str = "unconstrained"
    """'unconstrained' (from scratch) or 'constrained' (Lagrangian fine-tuning of ``init``)"""
    timesteps: int = 30_000
    """environment steps of this stage (one gradient step per environment step)"""
    seed: int = 0
    """seed of networks, environment, replay sampling and problem sampling"""
    out_dir: Optional[str] = None
    """output folder; default ``runs/<env>-<stage>-s<seed>``"""
    init: Optional[str] = None
    """checkpoint to start from (required for the constrained stage)"""
    sampler: str = "self"
    """training problems: 'self' (the paper's Algorithm 1), 'oracle' (SoRB's geodesic band), 'uniform'"""
    target_distance: Tuple[float, float] = (2.0, 15.0)
    """self-sampling: band of desired predicted distances (steps)"""
    target_cost: Optional[Tuple[float, float]] = None
    """self-sampling: band of desired predicted costs (None: distance only)"""
    cost_fraction: float = 0.5
    """self-sampling: share of the kept problems chosen with the cost target"""
    n_candidates: int = 1000
    """self-sampling: candidate pairs per refill (N)"""
    n_keep: int = 100
    """self-sampling: problems kept per refill (K)"""
    disagreement_weight: float = 0.0
    """self-sampling: bonus per unit of ensemble disagreement"""
    oracle_band: Tuple[float, float] = (2.0, 15.0)
    """oracle sampler: band of ground-truth geodesic goal distances (world units)"""
    cost_limit: float = 10.0
    """constrained stage: episode-cost limit delta"""
    lagrange_lr: float = 0.035
    """constrained stage: learning rate of lambda"""
    lagrange_init: float = 0.0
    """constrained stage: initial lambda"""
    lagrange_max: Optional[float] = None
    """constrained stage: optional cap on lambda"""
    lagrange_update_episodes: int = 10
    """constrained stage: episodes per lambda update"""
    batch_size: int = 64
    """minibatch size"""
    learning_rate: float = 3e-4
    """critic learning rate"""
    actor_learning_rate: Optional[float] = None
    """actor learning rate (default: learning_rate)"""
    buffer_size: int = 100_000
    """replay capacity"""
    learning_starts: int = 1000
    """random-action steps before learning"""
    n_critics: int = 3
    """distance ensemble size"""
    n_cost_critics: int = 3
    """cost ensemble size"""
    net_arch: List[int] = field(default_factory=lambda: [64, 64])
    """hidden widths of actor and critic heads"""
    encoder_arch: List[int] = field(default_factory=lambda: [64, 64])
    """hidden widths of the MLP observation encoder"""
    distance_bins: Optional[int] = None
    """bins of the distance distribution (default: the episode step limit)"""
    cost_bins: int = 40
    """atoms of the cost distribution"""
    cost_max: float = 40.0
    """largest cost atom"""
    action_noise: float = 0.2
    """std of the Gaussian exploration noise"""
    her_ratio: float = 0.5
    """fraction of replayed goals relabelled to future achieved goals"""
    random_goal_ratio: float = 0.0
    """fraction of replayed goals relabelled to random achieved goals"""
    eval_freq: int = 5000
    """environment steps between evaluations (and checkpoints)"""
    eval_problems: int = 200
    """evaluation: episodes on pairs within eval_max_distance"""
    eval_max_distance: float = 10.0
    """evaluation: largest geodesic distance of the episodes' pairs"""
    eval_pairs: int = 500
    """evaluation: pairs for the distance rank correlation"""
    eval_seed: int = 12345
    """evaluation: seed of the held-out problems"""
    threads: int = 1
    """torch threads"""
    progress_bar: bool = True
    """show a progress bar"""
    tensorboard_log: Optional[str] = None
    """TensorBoard folder (used when tensorboard is installed)"""
    verbose: int = 0
    """SB3 verbosity"""

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad setting."""
        if self.stage not in STAGES:
            raise ValueError(f"stage must be one of {STAGES}, got {self.stage!r}")
        if self.stage == "constrained" and not self.init:
            raise ValueError("the constrained stage fine-tunes a checkpoint: pass init (--init PATH)")
        if self.timesteps < 1:
            raise ValueError(f"timesteps must be >= 1, got {self.timesteps}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if self.eval_freq < 1:
            raise ValueError(f"eval_freq must be >= 1, got {self.eval_freq}")
        if self.init and not os.path.exists(self.init):
            raise FileNotFoundError(f"init checkpoint {self.init!r} does not exist")

    def resolved_out_dir(self) -> str:
        return self.out_dir or os.path.join("runs", f"{self.env_id.split(':')[-1]}-{self.stage}-s{self.seed}")


def _sampler_kwargs(cfg: TrainConfig) -> Dict[str, Any]:
    if cfg.sampler == "self":
        return dict(n_candidates=cfg.n_candidates, n_keep=cfg.n_keep, target_distance=tuple(cfg.target_distance),
                    target_cost=None if cfg.target_cost is None else tuple(cfg.target_cost),
                    cost_fraction=cfg.cost_fraction,
                    disagreement_weight=cfg.disagreement_weight, seed=cfg.seed)
    if cfg.sampler == "oracle":
        return dict(band=tuple(cfg.oracle_band))
    if cfg.sampler == "uniform":
        return {}
    raise ValueError(f"sampler must be 'self', 'oracle' or 'uniform', got {cfg.sampler!r}")


def build_model(cfg: TrainConfig):
    """The model of a stage: new (unconstrained) or loaded from ``cfg.init`` and set up for fine-tuning."""
    import gymnasium as gym
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.utils import FloatSchedule

    import safe_mapf_envs  # noqa: F401

    from .algorithm import SafeGoalTD3

    env = gym.make(cfg.env_id)
    noise = NormalActionNoise(np.zeros(env.action_space.shape), cfg.action_noise * np.ones(env.action_space.shape))
    sampler_kwargs = _sampler_kwargs(cfg)
    if cfg.init:
        model = SafeGoalTD3.load(cfg.init, env=env, device="cpu")
        if model.env_id is not None and model.env_id != cfg.env_id.split(":")[-1]:
            raise ValueError(f"checkpoint {cfg.init!r} was trained on {model.env_id!r}, not {cfg.env_id!r}")
        model.set_random_seed(cfg.seed)
        model.seed = cfg.seed
        model.action_noise = noise
        model.learning_starts = cfg.learning_starts
        model.batch_size = cfg.batch_size
        model.learning_rate = cfg.learning_rate
        model.actor_learning_rate = cfg.actor_learning_rate
        model._setup_lr_schedule()
        model.actor_lr_schedule = FloatSchedule(cfg.actor_learning_rate or cfg.learning_rate)
        model.cost_lr_schedule = FloatSchedule(cfg.learning_rate)
        model.replay_buffer.seed(cfg.seed)
        model.set_problem_sampler(cfg.sampler, **sampler_kwargs)
    else:
        bins = cfg.distance_bins or (env.spec.max_episode_steps if env.spec and env.spec.max_episode_steps else 20)
        model = SafeGoalTD3(
            "MultiInputPolicy", env, learning_rate=cfg.learning_rate, buffer_size=cfg.buffer_size,
            learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, action_noise=noise,
            replay_buffer_kwargs=dict(her_ratio=cfg.her_ratio, random_goal_ratio=cfg.random_goal_ratio),
            actor_learning_rate=cfg.actor_learning_rate,
            problem_sampler=cfg.sampler, problem_sampler_kwargs=sampler_kwargs, env_id=cfg.env_id.split(":")[-1],
            policy_kwargs=dict(net_arch=list(cfg.net_arch), n_critics=cfg.n_critics,
                               n_cost_critics=cfg.n_cost_critics, n_distance_bins=int(bins),
                               n_cost_bins=cfg.cost_bins, cost_max=cfg.cost_max,
                               features_extractor_kwargs={"net_arch": list(cfg.encoder_arch)}),
            tensorboard_log=cfg.tensorboard_log, verbose=cfg.verbose, seed=cfg.seed, device="cpu",
        )
    from .lagrangian import LagrangeMultiplier

    model.constrained = cfg.stage == "constrained"
    model.lagrange_update_episodes = cfg.lagrange_update_episodes
    if model.constrained:
        model.lagrangian = LagrangeMultiplier(cfg.cost_limit, cfg.lagrange_lr, cfg.lagrange_init, cfg.lagrange_max)
    return model


def _versions() -> Dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    return {"python": platform.python_version(), "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__, "gymnasium": gymnasium.__version__,
            "numpy": np.__version__, "machine": platform.machine(), "cpus": str(os.cpu_count())}


def train_stage(cfg: TrainConfig, command: Optional[List[str]] = None) -> Dict[str, Any]:
    """Run one stage and write its files (see the module docstring); return the summary."""
    import torch

    from .evaluation import PeriodicEvaluation

    cfg.validate()
    torch.set_num_threads(cfg.threads)
    out = cfg.resolved_out_dir()
    os.makedirs(out, exist_ok=True)
    config = {"config": dataclasses.asdict(cfg), "command": command if command is not None else sys.argv,
              "versions": _versions()}
    with open(os.path.join(out, "config.json"), "w") as f:
        json.dump(config, f, indent=2)
    eval_log = os.path.join(out, "evaluations.jsonl")
    if os.path.exists(eval_log):
        os.remove(eval_log)

    t0, c0 = time.time(), time.process_time()
    model = build_model(cfg)
    evaluation = PeriodicEvaluation(
        cfg.env_id, eval_freq=cfg.eval_freq, save_path=os.path.join(out, "checkpoint.zip"), log_path=eval_log,
        eval_kwargs=dict(n_problems=cfg.eval_problems, max_distance=cfg.eval_max_distance,
                         n_pairs=cfg.eval_pairs, seed=cfg.eval_seed), verbose=1)
    model.learn(cfg.timesteps, callback=evaluation, progress_bar=cfg.progress_bar,
                tb_log_name=f"{cfg.stage}-s{cfg.seed}")
    train_wall, train_cpu = time.time() - t0, time.process_time() - c0
    if evaluation.history and evaluation.history[-1]["timesteps"] == model.num_timesteps:
        final = evaluation.history[-1]
    else:
        final = evaluation.evaluate()
    model_path = os.path.join(out, "model.zip")
    model.save(model_path)
    summary = {
        "env_id": cfg.env_id, "stage": cfg.stage, "seed": cfg.seed, "timesteps": int(model.num_timesteps),
        "gradient_steps": int(model._n_updates), "wall_s": round(train_wall, 1), "cpu_s": round(train_cpu, 1),
        "lagrange_multiplier": model.lagrange_multiplier, "final_evaluation": final, "model": model_path,
    }
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    return summary


__all__ = ["STAGES", "TrainConfig", "build_model", "train_stage"]
