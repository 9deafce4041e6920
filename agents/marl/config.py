"""Settings of a multi-agent PPO run (``safe-mapf train-marl``), checked before any work."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

#: the trainers: parameter-shared independent PPO, and MAPPO with a cost critic and a Lagrange multiplier
ALGOS = ("ippo", "mappo-lag")


@dataclass
class MarlConfig:
    """Settings of one multi-agent training run (one parameter-shared policy for every agent)."""

    algo: str = "ippo"
    """'ippo' (SB3 PPO over SuperSuit's vector env) or 'mappo-lag' (centralised critics, Lagrangian cost)"""
    env_id: str = "SafeCenterDot-v0"
    """a registered id with vector observations (its map and keyword arguments)"""
    n_agents: int = 5
    """agents per training episode"""
    timesteps: int = 200_000
    """agent steps in all (environment steps x agents, agents already parked included)"""
    seed: int = 0
    """seed of networks, action sampling and the training problems"""
    max_cycles: int = 100
    """steps per training episode before truncation"""
    shaping: float = 0.0
    """weight of potential-based reward shaping by the straight-line distance to the goal (0: the env's reward)"""
    goal_distance: Optional[List[float]] = None
    """band ``[lo, hi]`` of geodesic start-goal distances of the training episodes (None: goals anywhere)"""
    n_envs: int = 4
    """environment copies stepped together (in this process)"""
    n_steps: int = 128
    """steps per environment copy per rollout"""
    batch_size: int = 512
    """minibatch size (agent steps)"""
    n_epochs: int = 5
    """passes over each rollout"""
    learning_rate: float = 3e-4
    """Adam learning rate of actor and critics"""
    gamma: float = 0.99
    """discount"""
    gae_lambda: float = 0.95
    """GAE lambda"""
    clip_range: float = 0.2
    """PPO clip range"""
    ent_coef: float = 0.0
    """entropy bonus"""
    net_arch: List[int] = field(default_factory=lambda: [64, 64])
    """hidden widths of actor and critics"""
    cost_limit: float = 2.0
    """mappo-lag: limit of an agent's episode cost"""
    lagrange_lr: float = 0.05
    """mappo-lag: step size of the multiplier per rollout"""
    lagrange_init: float = 0.0
    """mappo-lag: initial multiplier"""
    lagrange_start: int = 0
    """mappo-lag: agent steps before the multiplier starts to move (the policy first learns to arrive)"""
    eval_freq: int = 50_000
    """agent steps between evaluations and resume points (0: only at the end)"""
    eval_episodes: int = 10
    """episodes per evaluation (held-out seeds)"""
    eval_seed: int = 2024
    """seed of the evaluation episodes"""
    threads: int = 1
    """torch threads"""
    out_dir: Optional[str] = None
    """output folder; default ``runs/<env>-<algo>-s<seed>``"""
    resume: bool = False
    """continue the run in ``out_dir`` from its last resume point up to ``timesteps`` (with the run's own
    settings: see ``RESUMABLE_SETTINGS`` in :mod:`agents.marl.common`)"""
    overwrite: bool = False
    """start anew in an ``out_dir`` that holds an earlier run: the files it wrote are removed first"""
    progress_bar: bool = True
    """draw a progress bar"""
    tensorboard_log: Optional[str] = None
    """folder for TensorBoard event files"""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {list(ALGOS)}, got {self.algo!r}")
        from safe_mapf_envs.registration import check_env_id, env_spec

        self.env_id = check_env_id(self.env_id).split(":")[-1]
        if env_spec(self.env_id).obs_type != "vector":
            raise ValueError(f"{self.env_id} has panorama observations; the MARL trainers take vector ids "
                             "(e.g. SafeCenterDot-v0, SafeCentralObstacle-v0)")
        for name, lo in (("n_agents", 1), ("timesteps", 1), ("max_cycles", 1), ("n_envs", 1), ("n_steps", 2),
                         ("batch_size", 2), ("n_epochs", 1), ("eval_freq", 0), ("eval_episodes", 1),
                         ("lagrange_start", 0), ("threads", 1), ("seed", 0), ("eval_seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
        for name, positive, hi in (("learning_rate", True, math.inf), ("gamma", True, 1.0), ("gae_lambda", True, 1.0),
                                   ("clip_range", True, math.inf), ("lagrange_lr", False, math.inf),
                                   ("ent_coef", False, math.inf), ("cost_limit", False, math.inf),
                                   ("shaping", False, math.inf), ("lagrange_init", False, math.inf)):
            value = getattr(self, name)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and float(value) <= hi
            ok = ok and (float(value) > 0 if positive else float(value) >= 0)
            if not ok:
                bound = "> 0" if positive else ">= 0"
                raise ValueError(f"{name} must be a number {bound}" + (f" and <= {hi:g}" if hi < math.inf else "")
                                 + f", got {value!r}")
        if self.goal_distance is not None:
            band = list(self.goal_distance)
            if (len(band) != 2 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in band)
                    or not 0 <= band[0] < band[1]):
                raise ValueError(f"goal_distance must be two numbers 0 <= lo < hi, got {self.goal_distance!r}")
            self.goal_distance = [float(x) for x in band]
        if not self.net_arch or any(not isinstance(w, int) or w < 1 for w in self.net_arch):
            raise ValueError(f"net_arch must be positive integers, got {self.net_arch!r}")
        self.net_arch = list(self.net_arch)

    @property
    def rollout(self) -> int:
        """Agent steps per rollout."""
        return self.n_envs * self.n_steps * self.n_agents

    def env_kwargs(self, training: bool = True) -> Dict[str, Any]:
        """Keyword arguments of the training env (``training=False``: of the held-out evaluation, without
        shaping) beyond id, agents and length."""
        out: Dict[str, Any] = {"shaping": self.shaping, "gamma": self.gamma} if training and self.shaping else {}
        if self.goal_distance is not None:
            out["goal_distance"] = tuple(self.goal_distance)
        return out


__all__ = ["ALGOS", "MarlConfig"]
