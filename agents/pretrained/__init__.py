"""Checkpoints trained by this package's own training code, shipped as package data.

``load_pretrained("SafeCentralObstacle-v0", kind="unconstrained")`` returns a
:class:`~agents.algorithm.SafeGoalTD3` ready for ``predict``, ``distance``, ``cost``,
``pairwise_distance`` and ``pairwise_cost``. How each file was trained (command, steps, wall
time, measured figures) is recorded in this folder's README.md.
"""
from __future__ import annotations

import os
from typing import List, Optional, Tuple

KINDS = ("unconstrained", "constrained")

_HERE = os.path.dirname(os.path.abspath(__file__))


def pretrained_path(env_id: str, kind: str = "unconstrained") -> str:
    """Path of the shipped checkpoint for ``env_id`` and ``kind`` (``ValueError`` if there is none)."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    env_id = str(env_id).split(":")[-1]
    path = os.path.join(_HERE, f"{env_id}_{kind}.zip")
    if not os.path.exists(path):
        have = ", ".join(f"{e} ({k})" for e, k in available()) or "none"
        raise ValueError(f"no pretrained {kind} checkpoint for {env_id!r}; available: {have}")
    return path


def available() -> List[Tuple[str, str]]:
    """``(env_id, kind)`` of every shipped checkpoint."""
    out = []
    for name in sorted(os.listdir(_HERE)):
        if name.endswith(".zip") and "_" in name:
            env_id, kind = name[:-4].rsplit("_", 1)
            if kind in KINDS:
                out.append((env_id, kind))
    return out


def load_pretrained(env_id: str, kind: str = "unconstrained", device: str = "cpu",
                    path: Optional[str] = None):
    """Load the shipped ``kind`` checkpoint of ``env_id`` (or the checkpoint at ``path``).

    The checkpoint must have been trained on ``env_id`` and fit its observation and action
    spaces; otherwise :class:`~agents.checkpoints.CheckpointError` names the mismatch. It is read
    by :meth:`~agents.algorithm.SafeGoalTD3.load`, which unpickles nothing the file supplies and
    refuses corrupt, truncated, non-finite or unexpected files by name (see
    :mod:`agents.checkpoints`).
    """
    import gymnasium as gym

    import safe_mapf_envs  # noqa: F401

    from ..algorithm import SafeGoalTD3
    from ..checkpoints import CheckpointError

    env_id = str(env_id).split(":")[-1]
    ckpt = path if path is not None else pretrained_path(env_id, kind)
    model = SafeGoalTD3.load(ckpt, device=device)
    if model.env_id is not None and model.env_id != env_id:
        raise CheckpointError(f"{ckpt} was trained on {model.env_id!r}, not {env_id!r}")
    env = gym.make(env_id)
    for what, mine, theirs in (("observation", model.observation_space, env.observation_space),
                               ("action", model.action_space, env.action_space)):
        if mine != theirs:
            raise CheckpointError(f"{ckpt}: its {what} space {mine} does not match {env_id}'s {theirs}")
    env.close()
    return model


__all__ = ["KINDS", "available", "load_pretrained", "pretrained_path"]
