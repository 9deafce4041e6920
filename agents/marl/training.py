"""One multi-agent training run from a :class:`~agents.marl.config.MarlConfig` (``safe-mapf train-marl``)."""
from __future__ import annotations

from typing import Any, Dict, List, Optional

from .common import RunFolder
from .config import MarlConfig


def train_marl(cfg: MarlConfig, command: Optional[List[str]] = None) -> Dict[str, Any]:
    """Train ``cfg.algo`` and write the run folder (see :class:`~agents.marl.common.RunFolder`).

    ``command``: the command line, recorded in ``config.json``, ``model.json`` and ``summary.json``.
    Returns the summary (agent steps, wall and CPU time, the final held-out evaluation).
    """
    from ..threads import torch_threads

    run = RunFolder(cfg, command)
    with torch_threads(cfg.threads):
        if cfg.algo == "ippo":
            from .ippo import train_ippo

            return train_ippo(cfg, run)
        from .mappo_lag import train_mappo_lag

        return train_mappo_lag(cfg, run)


__all__ = ["train_marl"]
