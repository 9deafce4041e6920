"""Multi-agent RL baselines on the PettingZoo envs: IPPO and MAPPO-Lagrangian.

The paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe Reinforcement Learning"
reports multi-agent RL without search as "N/A"; these two make that column measurable:

- ``ippo``: one stable-baselines3 PPO policy shared by every agent, trained through
  SuperSuit's PettingZoo-to-vector-env wrappers (:mod:`agents.marl.ippo`);
- ``mappo-lag``: parameter-shared PPO with centralised reward and cost critics and a
  Lagrange multiplier on the episode cost (:mod:`agents.marl.mappo_lag`).

Both are goal-conditioned: each agent acts on its own ``[position, goal]``. Train with
:func:`train_marl` (``safe-mapf train-marl``); load with :func:`load_marl` or
:func:`load_marl_pretrained` and act with :meth:`MarlAgent.act`.
"""
from .common import evaluate_policy
from .config import ALGOS, MarlConfig
from .loading import MarlAgent, load_marl, load_marl_pretrained, pretrained_marl_path
from .training import train_marl

__all__ = ["ALGOS", "MarlAgent", "MarlConfig", "evaluate_policy", "load_marl", "load_marl_pretrained",
           "pretrained_marl_path", "train_marl"]
