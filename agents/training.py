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
from typing import Any, Dict, List, Optional, Tuple, cast

import numpy as np

from .run_folder import RunFolder, atomic_output, read_json, read_json_lines, write_atomic, write_json_atomic

STAGES = ("unconstrained", "constrained")


@dataclass
class TrainConfig:
    """Settings of one training stage."""

    env_id: str = "SafeCentralObstacle-v0"
    """a registered goal-conditioned environment id"""
    map_file: Optional[str] = None
    """the map file ``env_id`` was registered from (``safe-mapf train --map``), recorded with the run"""
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
    narrow_fraction: float = 0.0
    """self-sampling: share of each refill's problems that cross a narrow passage, not scored by the critic"""
    parked_agents: int = 0
    """other agents standing still on the way of each training episode (the env's ``parked_agents``)"""
    parked_fraction: float = 1.0
    """share of the training episodes that have the parked agents (the env's ``parked_fraction``)"""
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
    learning_rate: Optional[float] = None
    """critic learning rate (default: 3e-4 for vector observations, 1e-3 for panoramas)"""
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
    conv_layers: Optional[List[Tuple[int, int, int]]] = None
    """``(filters, kernel, stride)`` of each convolution of the image encoder (default: the
    paper's ``(16, 8, 4), (32, 4, 4)``, which reads only the top-left 20 x 20 pixels of a
    32 x 32 view; ``(16, 8, 4), (32, 3, 2)`` reads all of it, see :data:`FULL_VIEW_CONV_LAYERS`)"""
    share_encoder: Optional[bool] = None
    """one encoder for actor and critics, trained by the critic losses (default: for images)"""
    augmentation: Optional[str] = None
    """image augmentation of the shared encoder: None or 'shift' (DrQ's random shift); with
    ``init``, None keeps the checkpoint's setting"""
    actor_penalty: Optional[float] = None
    """weight of the actor's pre-tanh penalty (default: 0.01 for panoramas, 0 for vectors)"""
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
    eval_max_distance: Optional[float] = None
    """evaluation: largest geodesic distance of the episodes' pairs (default: 3 m on the
    apartments, 10 units on the 2D maps)"""
    eval_pairs: int = 500
    """evaluation: pairs for the distance rank correlation"""
    eval_pair_max_distance: Optional[float] = None
    """evaluation: largest geodesic distance of those pairs (default: 4 m on the apartments,
    15 units on the 2D maps)"""
    eval_seed: int = 12345
    """evaluation: seed of the held-out problems"""
    threads: int = 1
    """torch threads"""
    resume: bool = False
    """continue the run in out_dir from its last resume point (model, replay buffer, evaluations); the
    settings must be the run's own (see RESUMABLE_SETTINGS)"""
    overwrite: bool = False
    """start anew in an out_dir that holds an earlier run: its files (TRAIN_OUTPUTS) are removed first"""
    replay_save_freq: Optional[int] = None
    """environment steps between saves of the replay buffer for resuming (default: eval_freq;
    0: never)"""
    progress_bar: bool = True
    """show a progress bar"""
    tensorboard_log: Optional[str] = None
    """TensorBoard folder (used when tensorboard is installed)"""
    verbose: int = 0
    """SB3 verbosity"""

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad setting."""
        from safe_mapf_envs.registration import check_env_id

        check_env_id(self.env_id)
        if self.stage not in STAGES:
            raise ValueError(f"stage must be one of {STAGES}, got {self.stage!r}")
        if self.stage == "constrained" and not self.init:
            raise ValueError("the constrained stage fine-tunes a checkpoint: pass init (--init PATH)")
        if self.timesteps < 1:
            raise ValueError(f"timesteps must be >= 1, got {self.timesteps}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if not 0.0 <= self.narrow_fraction <= 1.0:
            raise ValueError(f"narrow_fraction must be in [0, 1], got {self.narrow_fraction!r}")
        if not isinstance(self.parked_agents, int) or self.parked_agents < 0:
            raise ValueError(f"parked_agents must be an integer >= 0, got {self.parked_agents!r}")
        if not 0.0 <= self.parked_fraction <= 1.0:
            raise ValueError(f"parked_fraction must be in [0, 1], got {self.parked_fraction!r}")
        if self.narrow_fraction > 0 and self.sampler != "self":
            raise ValueError("narrow_fraction shapes the self-sampler's candidates: use it with sampler 'self'")
        if self.eval_freq < 1:
            raise ValueError(f"eval_freq must be >= 1, got {self.eval_freq}")
        if self.conv_layers is not None:
            if not self.conv_layers or any(len(c) != 3 or min(int(v) for v in c) < 1 for c in self.conv_layers):
                raise ValueError("conv_layers must be one or more (filters, kernel, stride) triples of positive "
                                 f"integers, got {self.conv_layers!r}")
            if self.init:
                raise ValueError("conv_layers shapes a new encoder; a stage started from --init keeps the "
                                 "checkpoint's encoder")
        if self.init and not os.path.exists(self.init):
            raise FileNotFoundError(f"init checkpoint {self.init!r} does not exist")

    def resolved_learning_rate(self, image: bool) -> float:
        """The critic learning rate: the set one, else 1e-3 for image observations (the
        shared encoder learns several times faster than at 3e-4) and 3e-4 for vectors."""
        if self.learning_rate is not None:
            return float(self.learning_rate)
        return 1e-3 if image else 3e-4

    def eval_distances(self) -> Tuple[float, float]:
        """``(eval_max_distance, eval_pair_max_distance)`` with the env-dependent defaults."""
        lo, hi = default_eval_distances(self.env_id)
        return (self.eval_max_distance if self.eval_max_distance is not None else lo,
                self.eval_pair_max_distance if self.eval_pair_max_distance is not None else hi)

    def resolved_replay_save_freq(self) -> int:
        """Steps between resume points (0: none)."""
        return self.eval_freq if self.replay_save_freq is None else int(self.replay_save_freq)

    def resolved_out_dir(self) -> str:
        return self.out_dir or os.path.join("runs", f"{self.env_id.split(':')[-1]}-{self.stage}-s{self.seed}")


FULL_VIEW_CONV_LAYERS: Tuple[Tuple[int, int, int], ...] = ((16, 8, 4), (32, 3, 2))
"""An image encoder that reads every pixel of a 32 x 32 view (the paper's second layer,
``(32, 4, 4)``, reaches only the top-left 20 x 20): the first layer as in the paper, the second
with a 3 x 3 kernel at stride 2, a 3 x 3 map of 32 channels per view."""


def default_eval_distances(env_id: str) -> Tuple[float, float]:
    """Geodesic bands of the held-out figures: success on pairs within the first, distance rank
    correlation on pairs within the second (3 / 4 m on the apartments, 10 / 15 units on the 2D maps)."""
    from safe_mapf_envs.registration import env_spec

    try:
        layout = env_spec(env_id).layout
    except KeyError:
        return 10.0, 15.0
    return (3.0, 4.0) if layout.startswith("Apartment") else (10.0, 15.0)


def _sampler_kwargs(cfg: TrainConfig) -> Dict[str, Any]:
    if cfg.sampler == "self":
        return dict(n_candidates=cfg.n_candidates, n_keep=cfg.n_keep, target_distance=tuple(cfg.target_distance),
                    target_cost=None if cfg.target_cost is None else tuple(cfg.target_cost),
                    cost_fraction=cfg.cost_fraction,
                    disagreement_weight=cfg.disagreement_weight, seed=cfg.seed,
                    narrow_fraction=cfg.narrow_fraction)
    if cfg.sampler == "oracle":
        return dict(band=tuple(cfg.oracle_band))
    if cfg.sampler == "uniform":
        return {}
    raise ValueError(f"sampler must be 'self', 'oracle' or 'uniform', got {cfg.sampler!r}")


def _extractor_kwargs(cfg: TrainConfig) -> Dict[str, Any]:
    kwargs: Dict[str, Any] = {"net_arch": list(cfg.encoder_arch)}
    if cfg.conv_layers is not None:
        kwargs["conv_layers"] = [tuple(int(v) for v in c) for c in cfg.conv_layers]
    return kwargs


def make_training_env(cfg: TrainConfig):
    """The env a stage trains in: ``cfg.env_id``, with ``cfg.parked_agents`` parked agents on the way
    (in a ``cfg.parked_fraction`` share of its episodes)."""
    import gymnasium as gym

    import safe_mapf_envs  # noqa: F401

    kwargs: Dict[str, Any] = {}
    if cfg.parked_agents:
        kwargs["parked_agents"] = cfg.parked_agents
        if cfg.parked_fraction < 1.0:
            kwargs["parked_fraction"] = cfg.parked_fraction
    return gym.make(cfg.env_id, **kwargs)


def build_model(cfg: TrainConfig):
    """The model of a stage: new (unconstrained) or loaded from ``cfg.init`` and set up for fine-tuning."""
    import gymnasium as gym
    from stable_baselines3.common.noise import NormalActionNoise

    import safe_mapf_envs  # noqa: F401

    from .algorithm import SafeGoalTD3
    from .encoders import is_image_space

    env = make_training_env(cfg)
    obs_space = cast(gym.spaces.Dict, env.observation_space)
    image = is_image_space(obs_space["observation"])
    shape = cast(Tuple[int, ...], env.action_space.shape)
    noise = NormalActionNoise(np.zeros(shape), cfg.action_noise * np.ones(shape))
    sampler_kwargs = _sampler_kwargs(cfg)
    constrained = cfg.stage == "constrained"
    lagrange: Dict[str, Any] = {}
    if constrained:
        lagrange = dict(cost_limit=cfg.cost_limit, lagrange_lr=cfg.lagrange_lr, lagrange_init=cfg.lagrange_init,
                        lagrange_max=cfg.lagrange_max)
    # with parked agents, achieved goals are rendered without them and differ from observations
    buffer_kwargs = dict(her_ratio=cfg.her_ratio, random_goal_ratio=cfg.random_goal_ratio,
                         achieved_goal_is_observation=image and not cfg.parked_agents)
    if cfg.init:
        kept: Dict[str, Any] = {} if cfg.augmentation is None else {"augmentation": cfg.augmentation}
        if cfg.parked_agents:
            kept["replay_buffer_kwargs"] = buffer_kwargs
        model = SafeGoalTD3.load(
            cfg.init, env=env, device="cpu", seed=cfg.seed, action_noise=noise, learning_starts=cfg.learning_starts,
            batch_size=cfg.batch_size, learning_rate=cfg.resolved_learning_rate(image),
            actor_learning_rate=cfg.actor_learning_rate, problem_sampler=cfg.sampler,
            problem_sampler_kwargs=sampler_kwargs, constrained=constrained,
            lagrange_update_episodes=cfg.lagrange_update_episodes, tensorboard_log=cfg.tensorboard_log,
            **kept, **lagrange)  # augmentation None: the checkpoint's setting
        if model.env_id is not None and model.env_id != cfg.env_id.split(":")[-1]:
            raise ValueError(f"checkpoint {cfg.init!r} was trained on {model.env_id!r}, not {cfg.env_id!r}")
        return model
    bins = cfg.distance_bins or (env.spec.max_episode_steps if env.spec and env.spec.max_episode_steps else 20)
    return SafeGoalTD3(
        "MultiInputPolicy", env, learning_rate=cfg.resolved_learning_rate(image), buffer_size=cfg.buffer_size,
        learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, action_noise=noise,
        replay_buffer_kwargs=buffer_kwargs,
        actor_learning_rate=cfg.actor_learning_rate,
        problem_sampler=cfg.sampler, problem_sampler_kwargs=sampler_kwargs, env_id=cfg.env_id.split(":")[-1],
        policy_kwargs=dict(net_arch=list(cfg.net_arch), n_critics=cfg.n_critics,
                           n_cost_critics=cfg.n_cost_critics, n_distance_bins=int(bins),
                           n_cost_bins=cfg.cost_bins, cost_max=cfg.cost_max, share_encoder=cfg.share_encoder,
                           features_extractor_kwargs=_extractor_kwargs(cfg)),
        augmentation=cfg.augmentation,
        actor_preactivation_penalty=(cfg.actor_penalty if cfg.actor_penalty is not None
                                     else (0.01 if image else 0.0)),
        constrained=constrained, lagrange_update_episodes=cfg.lagrange_update_episodes, **lagrange,
        tensorboard_log=cfg.tensorboard_log, verbose=cfg.verbose, seed=cfg.seed, device="cpu",
    )


def _versions() -> Dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    return {"python": platform.python_version(), "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__, "gymnasium": gymnasium.__version__,
            "numpy": np.__version__, "machine": platform.machine(), "cpus": str(os.cpu_count())}


class ResumeCheckpoint:
    """Everything a run needs to continue after an interruption, in ``<out_dir>/resume/``: the
    model (networks, optimisers, multiplier, step counter), the replay buffer's filled part and
    ``state.json`` (the step of the resume point, wall and CPU time so far).

    Written every ``freq`` environment steps. The model and buffer files of a resume point carry
    its step in their names and ``state.json`` is replaced last, atomically: a run killed at any
    moment leaves ``state.json`` naming a complete resume point."""

    def __init__(self, out_dir: str) -> None:
        self.dir = os.path.join(out_dir, "resume")

    def _state_path(self) -> str:
        return os.path.join(self.dir, "state.json")

    def exists(self) -> bool:
        return os.path.exists(self._state_path())

    def save(self, model: Any, wall_s: float, cpu_s: float, replay: bool = True) -> None:
        os.makedirs(self.dir, exist_ok=True)
        step = int(model.num_timesteps)
        model_name, replay_name = f"model-{step}.zip", f"replay-{step}.npz"
        with atomic_output(os.path.join(self.dir, model_name)) as tmp:
            model.save(tmp)
        if replay:
            model.replay_buffer.save_arrays(os.path.join(self.dir, replay_name))
        state = {"timesteps": step, "wall_s": round(wall_s, 1), "cpu_s": round(cpu_s, 1),
                 "gradient_steps": int(model._n_updates), "model": model_name,
                 "replay": replay_name if replay else None}
        write_json_atomic(self._state_path(), state)
        for name in os.listdir(self.dir):  # the files of earlier resume points
            if name not in (model_name, replay_name, "state.json") and not name.startswith("."):
                os.remove(os.path.join(self.dir, name))

    def state(self) -> Dict[str, Any]:
        """The saved state (``ValueError`` naming the file if it is unreadable or incomplete)."""
        state = read_json(self._state_path(), what="resume state")
        if isinstance(state, dict) and "model" not in state and isinstance(state.get("replay"), bool):
            state["model"] = "model.zip"  # a resume point written with fixed file names
            state["replay"] = "replay.npz" if state["replay"] else None
        if not isinstance(state, dict) or not {"timesteps", "wall_s", "cpu_s", "model"} <= set(state):
            raise ValueError(f"resume state {self._state_path()!r} lacks timesteps, wall_s, cpu_s or model")
        for key in ("model", "replay"):
            name = state.get(key)
            if name is not None and not os.path.exists(os.path.join(self.dir, name)):
                raise ValueError(f"resume state {self._state_path()!r} names {name}, which is not in {self.dir!r}")
        return state

    def load(self, cfg: "TrainConfig"):
        """The saved model (with its replay buffer) set up for ``cfg``, and the saved state."""
        from .algorithm import SafeGoalTD3

        state = self.state()
        model = SafeGoalTD3.load(os.path.join(self.dir, state["model"]), env=make_training_env(cfg), device="cpu")
        if state.get("replay"):
            model.replay_buffer.load_arrays(os.path.join(self.dir, state["replay"]))
        return model, state


def _make_callbacks(cfg: "TrainConfig", out: str, eval_log: str, resume: ResumeCheckpoint,
                    clock: Dict[str, float]):
    from stable_baselines3.common.callbacks import BaseCallback

    from .evaluation import PeriodicEvaluation

    max_d, pair_d = cfg.eval_distances()
    evaluation = PeriodicEvaluation(
        cfg.env_id, eval_freq=cfg.eval_freq, save_path=os.path.join(out, "checkpoint.zip"), log_path=eval_log,
        eval_kwargs=dict(n_problems=cfg.eval_problems, max_distance=max_d, n_pairs=cfg.eval_pairs,
                         pair_max_distance=pair_d, seed=cfg.eval_seed), verbose=1,
        wall_offset=clock["wall0"], cpu_offset=clock["cpu0"])
    freq = cfg.resolved_replay_save_freq()

    class _Resume(BaseCallback):
        """Writes a resume point at the start of a rollout, after the gradient steps of the steps before
        it, so that a resumed run takes every gradient step an uninterrupted one takes."""

        def __init__(self) -> None:
            super().__init__()
            self._last = 0

        def _on_training_start(self) -> None:
            self._last = self.num_timesteps - self.num_timesteps % freq if freq > 0 else self.num_timesteps

        def _on_rollout_start(self) -> None:
            if freq > 0 and self.num_timesteps - self._last >= freq:
                self._last = self.num_timesteps
                resume.save(self.model, clock["wall0"] + time.time() - clock["t0"],
                            clock["cpu0"] + time.process_time() - clock["c0"])

        def _on_step(self) -> bool:
            return True

    return evaluation, [evaluation, _Resume()]


#: what ``train_stage`` writes into its folder (``overwrite`` removes these, and only these)
TRAIN_OUTPUTS = ("model.zip", "checkpoint.zip", "config.json", "evaluations.jsonl", "summary.json", "resume")
#: settings a resumed run may change; every other one must be the run's own
RESUMABLE_SETTINGS = ("timesteps", "out_dir", "resume", "overwrite", "threads", "progress_bar", "tensorboard_log",
                      "verbose", "replay_save_freq")


def _flag(key: str) -> str:
    """The ``safe-mapf train`` option of a setting, for messages."""
    return {"env_id": "--env", "out_dir": "--out"}.get(key, "--" + key.replace("_", "-"))


def output_folder(cfg: TrainConfig) -> RunFolder:
    """The run's output folder (see :class:`~agents.run_folder.RunFolder`)."""
    return RunFolder(cfg.resolved_out_dir(), "safe-mapf train", TRAIN_OUTPUTS, "config.json", settings_key="config")


def check_run(cfg: TrainConfig) -> None:
    """Every check of a stage before any work or any file is written: the settings, the ``init``
    checkpoint, and what the output folder allows (see ``resume`` and ``overwrite``)."""
    cfg.validate()
    if cfg.init:
        from .checkpoints import check_checkpoint

        check_checkpoint(cfg.init)
    output_folder(cfg).check(dataclasses.asdict(cfg), resume=cfg.resume, overwrite=cfg.overwrite,
                             may_differ=RESUMABLE_SETTINGS, describe=_flag)
    if cfg.resume:
        point = ResumeCheckpoint(cfg.resolved_out_dir())
        if not point.exists():
            raise ValueError(f"nothing to resume in {cfg.resolved_out_dir()!r}: no resume point (resume/state.json, "
                             "written every replay_save_freq steps)")
        point.state()  # whole and readable


def train_stage(cfg: TrainConfig, command: Optional[List[str]] = None) -> Dict[str, Any]:
    """Run one stage and write its files (see the module docstring); return the summary.

    A folder that holds files is refused unless ``cfg.resume`` (continue the run in it, from the
    resume point written every ``replay_save_freq`` steps, up to ``cfg.timesteps`` steps in all;
    the settings must be the run's own, :data:`RESUMABLE_SETTINGS` aside) or ``cfg.overwrite``
    (remove what an earlier run wrote, :data:`TRAIN_OUTPUTS`). A resumed run keeps the evaluation
    log, and its wall and CPU times and step counts cover every part of the run.
    """
    import torch

    check_run(cfg)
    torch.set_num_threads(cfg.threads)
    out = cfg.resolved_out_dir()
    resume = ResumeCheckpoint(out)
    extra = {"command": command if command is not None else sys.argv, "versions": _versions()}
    output_folder(cfg).prepare(dataclasses.asdict(cfg), resume=cfg.resume, overwrite=cfg.overwrite,
                               may_differ=RESUMABLE_SETTINGS, describe=_flag, extra=extra)
    eval_log = os.path.join(out, "evaluations.jsonl")

    clock = {"t0": time.time(), "c0": time.process_time(), "wall0": 0.0, "cpu0": 0.0}
    if cfg.resume:
        model, state = resume.load(cfg)
        clock["wall0"], clock["cpu0"] = float(state["wall_s"]), float(state["cpu_s"])
        if os.path.exists(eval_log):  # drop evaluations made after the resume point
            kept = [r for r in read_json_lines(eval_log) if r.get("timesteps", 0) <= model.num_timesteps]
            write_atomic(eval_log, "".join(json.dumps(r) + "\n" for r in kept))
    else:
        model = build_model(cfg)
    evaluation, callbacks = _make_callbacks(cfg, out, eval_log, resume, clock)
    remaining = cfg.timesteps - int(model.num_timesteps) if cfg.resume else cfg.timesteps
    if remaining > 0:
        model.learn(remaining, callback=callbacks, progress_bar=cfg.progress_bar,
                    tb_log_name=f"{cfg.stage}-s{cfg.seed}", reset_num_timesteps=not cfg.resume)
    train_wall = clock["wall0"] + time.time() - clock["t0"]
    train_cpu = clock["cpu0"] + time.process_time() - clock["c0"]
    if cfg.resolved_replay_save_freq() > 0 and remaining > 0:  # the end is a resume point too: a run may go on
        resume.save(model, train_wall, train_cpu)
    if evaluation.history and evaluation.history[-1]["timesteps"] == model.num_timesteps:
        final = evaluation.history[-1]
    else:
        final = evaluation.evaluate()
    model_path = os.path.join(out, "model.zip")
    with atomic_output(model_path) as tmp:
        model.save(tmp)
    summary = {
        "env_id": cfg.env_id, "stage": cfg.stage, "seed": cfg.seed, "timesteps": int(model.num_timesteps),
        "gradient_steps": int(model._n_updates), "wall_s": round(train_wall, 1), "cpu_s": round(train_cpu, 1),
        "lagrange_multiplier": model.lagrange_multiplier, "final_evaluation": final, "model": model_path,
    }
    write_json_atomic(os.path.join(out, "summary.json"), summary)
    return summary


__all__ = ["RESUMABLE_SETTINGS", "STAGES", "TRAIN_OUTPUTS", "ResumeCheckpoint", "TrainConfig", "build_model",
           "check_run", "default_eval_distances", "output_folder", "train_stage"]
