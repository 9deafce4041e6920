"""Loading trained multi-agent policies: :class:`MarlAgent`, :func:`load_marl`, :func:`load_marl_pretrained`.

Above both trainers (:mod:`agents.marl.ippo`, :mod:`agents.marl.mappo_lag`), whose savers it reads.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Mapping, Optional

import numpy as np

from ..run_folder import read_json
from .common import SUFFIX, Act, flat_observations
from .config import ALGOS
from .ippo import load_ppo, ppo_act
from .mappo_lag import mappo_act, read_mappo_checkpoint


class MarlAgent:
    """A trained parameter-shared policy: the same network acts for every agent, from its own
    flat observation ``[position, goal]``; ``act`` is deterministic (the policy's mean action).

    Load one with :func:`load_marl` or :func:`load_marl_pretrained`.
    """

    def __init__(self, act: Act, meta: Dict[str, Any]) -> None:
        self._act = act
        self.meta = dict(meta)
        self.algo: str = meta["algo"]
        self.env_id: str = meta["env_id"]
        self.obs_dim: int = int(meta["obs_dim"])

    def act(self, observations: np.ndarray) -> np.ndarray:
        """Actions ``(n, 2)`` for ``n`` agents' flat observations ``(n, obs_dim)``."""
        obs = np.asarray(observations, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"{self.algo} policy: expected observations of shape (n, {self.obs_dim}), "
                             f"got {obs.shape}")
        return np.asarray(self._act(obs), dtype=np.float32).reshape(len(obs), -1)

    def act_dict(self, observations: Mapping[str, Any]) -> Dict[str, np.ndarray]:
        """Actions keyed by agent, for a PettingZoo observation dict (Dict or flat observations)."""
        names = list(observations)
        return dict(zip(names, self.act(flat_observations(observations, names)))) if names else {}

    def __repr__(self) -> str:
        return f"MarlAgent({self.algo!r}, {self.env_id!r}, timesteps={self.meta.get('timesteps')})"


def load_marl(path: str, env_id: Optional[str] = None) -> MarlAgent:
    """Load a policy saved by ``safe-mapf train-marl`` (its ``model.json`` must lie beside it).

    ``env_id``: raise ``ValueError`` if the policy was trained on another map.

    Nothing the files supply is unpickled: an IPPO file (a stable-baselines3 PPO archive) is read
    by :func:`~agents.marl.ippo.load_ppo`, a MAPPO-Lagrangian file by
    :func:`~agents.marl.mappo_lag.read_mappo_checkpoint`. A truncated, corrupt or non-finite file,
    or a description that does not fit it, raises ``ValueError`` naming the file.
    """
    p = Path(path)
    meta_path = p.with_suffix(".json")
    if not p.exists():
        raise ValueError(f"no MARL checkpoint at {path}")
    if not meta_path.exists():
        raise ValueError(f"{path}: its description {meta_path.name} is missing (written next to it by train-marl)")
    meta = read_json(meta_path, what="policy description")
    if not isinstance(meta, dict):
        raise ValueError(f"{meta_path} is not a description of a MARL policy (not a JSON object)")
    missing = [k for k in ("algo", "env_id", "obs_dim") if k not in meta]
    if missing:
        raise ValueError(f"{meta_path} is missing the keys {missing}")
    if env_id is not None and meta.get("env_id") != str(env_id).split(":")[-1]:
        raise ValueError(f"{path} was trained on {meta.get('env_id')!r}, not {env_id!r}")
    if meta.get("algo") == "ippo":
        model = load_ppo(str(p))
        act, obs_dim = ppo_act(model), int(np.prod(model.observation_space.shape))
    elif meta.get("algo") == "mappo-lag":
        ckpt = read_mappo_checkpoint(str(p))
        act, obs_dim = mappo_act(ckpt, str(p)), int(ckpt["obs_dim"])
    else:
        raise ValueError(f"{meta_path}: unknown algo {meta.get('algo')!r}")
    if obs_dim != int(meta["obs_dim"]):
        raise ValueError(f"{path} takes observations of {obs_dim} values, its description {meta_path.name} "
                         f"says {meta['obs_dim']}")
    return MarlAgent(act, meta)


_PRETRAINED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "pretrained")


def pretrained_marl_path(env_id: str, algo: str) -> str:
    """Path of the shipped ``algo`` policy of ``env_id`` (``ValueError`` if none is shipped)."""
    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
    env_id = str(env_id).split(":")[-1]
    path = os.path.join(_PRETRAINED, f"{env_id}_{algo.replace('-', '_')}{SUFFIX[algo]}")
    if not os.path.exists(path):
        have = sorted(n for n in os.listdir(_PRETRAINED) if n.endswith((".pt", "_ippo.zip")))
        raise ValueError(f"no shipped {algo} policy for {env_id!r}; shipped: {', '.join(have) or 'none'}")
    return path


def load_marl_pretrained(env_id: str, algo: str, path: Optional[str] = None) -> MarlAgent:
    """The shipped ``algo`` policy of ``env_id`` (or the one at ``path``, checked against ``env_id``)."""
    return load_marl(path if path is not None else pretrained_marl_path(env_id, algo), env_id=env_id)


__all__ = ["MarlAgent", "load_marl", "load_marl_pretrained", "pretrained_marl_path"]
