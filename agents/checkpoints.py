"""Reading checkpoints of the safe agent: what makes a file loadable, and the error when it is not."""
from __future__ import annotations

import io
import pathlib
import zipfile
from typing import Any, Dict, Optional, Union

import torch as th
from stable_baselines3.common.save_util import load_from_zip_file

from .policies import SafeGoalPolicy


class CheckpointError(ValueError):
    """A checkpoint that cannot be loaded: corrupt, truncated, incomplete or for another setup."""


def check_checkpoint(path: Union[str, pathlib.Path, io.BufferedIOBase], device: Union[th.device, str] = "auto",
                     custom_objects: Optional[Dict[str, Any]] = None, owner: str = "SafeGoalTD3") -> str:
    """Check that ``path`` is a complete checkpoint of a :class:`~agents.policies.SafeGoalPolicy`
    agent before Stable-Baselines3 loads it, so that a bad file gives a :class:`CheckpointError`
    naming the problem (``FileNotFoundError`` for a missing file); ``owner`` names the algorithm
    in the messages. Returns the name to use in later messages."""
    name = str(path) if not isinstance(path, io.BufferedIOBase) else "<stream>"
    if isinstance(path, (str, pathlib.Path)):
        p = pathlib.Path(path)
        if not p.exists() and not p.with_suffix(".zip").exists():
            raise FileNotFoundError(f"no checkpoint at {name}")
    try:
        data, params, _ = load_from_zip_file(path, device=device, custom_objects=custom_objects)
    except (zipfile.BadZipFile, EOFError, OSError) as exc:
        raise CheckpointError(f"{name} is not a readable checkpoint (truncated or corrupt zip): {exc}") from exc
    except Exception as exc:  # unpickling or torch deserialisation errors
        if "zip-file" in str(exc):  # SB3 reports a bad zip as ValueError
            raise CheckpointError(f"{name} is not a readable checkpoint (truncated or corrupt zip)") from exc
        raise CheckpointError(f"{name}: could not deserialise the checkpoint "
                              f"({type(exc).__name__}: {exc})") from exc
    if data is None:
        raise CheckpointError(f"{name} has no 'data' entry (not an SB3 checkpoint, or incomplete)")
    missing = [k for k in ("policy_class", "observation_space", "action_space") if k not in data]
    if missing:
        raise CheckpointError(f"{name} is missing the keys {missing} in its 'data' entry")
    policy_class = data["policy_class"]
    if not (isinstance(policy_class, type) and issubclass(policy_class, SafeGoalPolicy)):
        raise CheckpointError(f"{name} holds a {getattr(policy_class, '__name__', policy_class)!r} policy, "
                              f"not a SafeGoalPolicy: it was not saved by {owner}")
    needed = ["policy", "actor.optimizer", "critic.optimizer", "cost_critic.optimizer"]
    absent = [k for k in needed if not params or k not in params]
    if absent:
        raise CheckpointError(f"{name} is missing the parameter files {[k + '.pth' for k in absent]}")
    return name


__all__ = ["CheckpointError", "check_checkpoint"]
