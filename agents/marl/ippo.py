"""IPPO: one stable-baselines3 PPO policy shared by every agent, over SuperSuit's vector env.

The path PettingZoo documents for SB3: ``black_death_v3`` keeps an agent that reached its goal in
the vector env (zero observations, its actions ignored) until the episode ends, so every
slot of the vector env stays filled; ``pettingzoo_env_to_vec_env_v1`` makes each agent one
environment of an SB3 ``VecEnv`` and ``concat_vec_envs_v1`` stacks ``n_envs`` copies. Each
agent sees its own flat observation ``[position, goal]`` (goal-conditioned), and PPO's
critic sees the same: the critic is independent, as in IPPO.
"""
from __future__ import annotations

from typing import Any, Dict

import numpy as np

from .common import Act, RunFolder, make_env
from .config import MarlConfig


def make_vec_env(cfg: MarlConfig):
    """SuperSuit's SB3 vector env over ``cfg.n_envs`` copies of the ``cfg.n_agents``-agent env."""
    import supersuit as ss

    par = make_env(cfg.env_id, cfg.n_agents, cfg.max_cycles, **cfg.env_kwargs())
    return ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(ss.black_death_v3(par)), cfg.n_envs,
                                 num_cpus=0, base_class="stable_baselines3")


def train_ippo(cfg: MarlConfig, run: RunFolder) -> Dict[str, Any]:
    """Train (or resume) IPPO as ``cfg`` says, writing into ``run``; returns the run's summary."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.utils import set_random_seed

    venv = make_vec_env(cfg)
    # SuperSuit's concatenated env has no seed(), which PPO(seed=...) calls: seed each copy by a reset
    # (copy i with seed + i; a resumed run draws new problems) and the generators as PPO would
    seed = cfg.seed + run.start_steps
    venv.venv.reset(seed=seed)
    set_random_seed(seed)
    if run.start_steps:
        model = load_ppo(str(run.checkpoint), env=venv, tensorboard_log=cfg.tensorboard_log)
    else:
        model = PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                    learning_rate=cfg.learning_rate, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda,
                    clip_range=cfg.clip_range, ent_coef=cfg.ent_coef, policy_kwargs={"net_arch": list(cfg.net_arch)},
                    tensorboard_log=cfg.tensorboard_log, device="cpu", verbose=0)
    model.action_space.seed(seed)

    def act(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    obs_dim = int(np.prod(venv.observation_space.shape))

    class Periodic(BaseCallback):
        """Progress bar, and every ``eval_freq`` agent steps an evaluation and a resume point."""

        def __init__(self) -> None:
            super().__init__()
            self.last = run.start_steps

        def _on_step(self) -> bool:
            run.advance(venv.num_envs)
            if cfg.eval_freq and self.num_timesteps - self.last >= cfg.eval_freq:
                self.last = self.num_timesteps
                ev = run.evaluate(act, self.num_timesteps)
                run.save_checkpoint(model.save, self.num_timesteps, obs_dim)
                if run.bar is not None:
                    run.bar.set_postfix_str(f"success={ev['success_rate']:.2f} cost={ev['mean_cost']:.2f}")
            return True

    run.open_bar()
    remaining = max(cfg.timesteps - run.start_steps, 0)
    model.learn(remaining, callback=Periodic(), reset_num_timesteps=run.start_steps == 0, tb_log_name="ippo")
    steps = int(model.num_timesteps)
    run.save_file(model.save, run.out / "model.zip")
    run.evaluate(act, steps)
    run.save_checkpoint(model.save, steps, obs_dim)
    venv.close()
    return run.finish(steps, obs_dim)


def _ppo_spec():
    from stable_baselines3.common.buffers import RolloutBuffer  # noqa: F401  (imports the base classes named)
    from stable_baselines3.common.policies import ActorCriticPolicy  # noqa: F401

    from ..checkpoints import ArchiveSpec, class_rebuilder, schedule_rebuilder

    return ArchiveSpec(
        owner="IPPO (stable-baselines3 PPO)",
        policy_base=("stable_baselines3.common.policies", "ActorCriticPolicy"),
        params=("policy", "policy.optimizer"),
        rebuilders={"rollout_buffer_class": class_rebuilder(("stable_baselines3.common.buffers", "RolloutBuffer")),
                    "clip_range": schedule_rebuilder, "clip_range_vf": schedule_rebuilder},
    )


def load_ppo(path: str, env: Any = None, **kwargs: Any):
    """The stable-baselines3 PPO model saved at ``path``, read without unpickling anything (see
    :mod:`agents.checkpoints`): a corrupt, truncated, non-finite or unexpected file raises
    :class:`~agents.checkpoints.CheckpointError` naming the file and the entry."""
    from stable_baselines3 import PPO

    from ..checkpoints import CheckpointError, read_sb3_archive

    archive = read_sb3_archive(path, _ppo_spec(), env=env, provided=list(kwargs))
    try:
        return PPO.load(archive.stream(), env=env, device="cpu", custom_objects=archive.custom_objects, **kwargs)
    except (ValueError, RuntimeError, KeyError, AssertionError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"{archive.name}: not a loadable PPO checkpoint ({type(exc).__name__}: {exc})") from exc


def ppo_act(model: Any) -> Act:
    """The deterministic action function of a PPO model."""

    def act(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    return act


def load_ippo_act(path: str) -> Act:
    """The deterministic action function of an IPPO checkpoint (read by :func:`load_ppo`)."""
    return ppo_act(load_ppo(path))


__all__ = ["load_ippo_act", "load_ppo", "make_vec_env", "ppo_act", "train_ippo"]
