"""Goal-conditioned safe agents (learning) and search on the replay buffer (planning).

Learning (this package's top level):

- :class:`SafeGoalTD3`: the Stable-Baselines3 algorithm (distance and cost critics, Lagrangian
  fine-tuning, self-sampling), with ``distance``, ``cost``, ``pairwise_distance`` and
  ``pairwise_cost`` for planners;
- :func:`load_pretrained`: the checkpoints shipped with the package;
- :class:`ProblemSamplingCallback`: a problem sampler for ``learn(callback=...)``;
- :func:`inference_threads`: the CPU threads of critic queries (one by default, see
  :mod:`agents.threads`).

Names are imported lazily, so ``import agents.search`` does not pull in torch.
"""
from __future__ import annotations

import importlib
import sys
from importlib import metadata as _metadata
from typing import Any

try:
    #: The installed distribution's version (``safe-mapf``; the same as ``safe_mapf_envs.__version__``).
    __version__ = _metadata.version("safe-mapf")
except _metadata.PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"

# whether torch was imported before this package (agents.threads then cannot read torch's
# start-up thread count and estimates it)
_TORCH_PRELOADED = "torch" in sys.modules

_EXPORTS = {
    "SafeGoalTD3": "agents.algorithm",
    "CheckpointError": "agents.checkpoints",
    "SafeGoalPolicy": "agents.policies",
    "GoalCostReplayBuffer": "agents.buffers",
    "LagrangeMultiplier": "agents.lagrangian",
    "SelfSampler": "agents.self_sampling",
    "OracleSampler": "agents.self_sampling",
    "UniformSampler": "agents.self_sampling",
    "ProblemResetWrapper": "agents.self_sampling",
    "ProblemSamplingCallback": "agents.self_sampling",
    "load_pretrained": "agents.pretrained",
    "inference_threads": "agents.threads",
    "pretrained_path": "agents.pretrained",
    "evaluate_agent": "agents.evaluation",
    "TrainConfig": "agents.training",
    "train_stage": "agents.training",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))
