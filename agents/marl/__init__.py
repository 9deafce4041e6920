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

Names are imported lazily, so reading :class:`MarlConfig` (``safe-mapf train-marl --help``) does
not pull in torch.
"""
from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "ALGOS": "agents.marl.config",
    "MarlConfig": "agents.marl.config",
    "evaluate_policy": "agents.marl.common",
    "MarlAgent": "agents.marl.loading",
    "load_marl": "agents.marl.loading",
    "load_marl_pretrained": "agents.marl.loading",
    "pretrained_marl_path": "agents.marl.loading",
    "train_marl": "agents.marl.training",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'agents.marl' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_EXPORTS))
