"""Input checks and message formatting shared by the environments.

Every check raises ``ValueError`` with a message that names the argument and shows the value
with plain numbers (``27.5``, not ``np.float64(27.5)``).
"""
from __future__ import annotations

import difflib
import warnings
from collections.abc import Mapping
from typing import Any, Dict, Iterable, Optional, Sequence, Tuple, Union

import numpy as np


def show(value: Any) -> str:
    """``value`` for an error message: numbers, numpy scalars and arrays as plain Python numbers.

    ``show(np.float64(27.5))`` is ``"27.5"``, ``show((np.float64(1.0), np.nan))`` is
    ``"(1.0, nan)"``, ``show(np.array([1.0, 2.0]))`` is ``"[1.0, 2.0]"``; anything else is its
    ``repr``.
    """
    if isinstance(value, np.ndarray):
        return repr(value.tolist()) if value.size <= 16 else f"array of shape {value.shape}"
    if isinstance(value, np.generic):
        return repr(value.item())
    if isinstance(value, tuple):
        inner = ", ".join(show(v) for v in value)
        return f"({inner},)" if len(value) == 1 else f"({inner})"
    if isinstance(value, list):
        return "[" + ", ".join(show(v) for v in value) + "]"
    return repr(value)


def show_point(p: Union[Sequence[float], np.ndarray]) -> str:
    """A 2D point as ``(x, y)`` with plain numbers."""
    return f"({float(p[0])!r}, {float(p[1])!r})"


def plural(n: int, word: str) -> str:
    """``"1 agent"``, ``"2 agents"``."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def check_count(value: Any, name: str, minimum: int) -> int:
    """``value`` as an ``int``; ``ValueError`` unless it is an integer (not a bool) >= ``minimum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {show(value)}")
    return int(value)


def check_number(value: Any, name: str, *, minimum: float = 0.0, strict: bool = False) -> float:
    """``value`` as a finite ``float`` that is ``>= minimum`` (``> minimum`` with ``strict``)."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if ok:
        v = float(value)
        ok = bool(np.isfinite(v)) and (v > minimum if strict else v >= minimum)
    if not ok:
        bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
        raise ValueError(f"{name} must be a finite number {bound}, got {show(value)}")
    return float(value)


def check_band(band: Any, name: str = "goal_distance") -> Tuple[float, float]:
    """A ``(lo, hi)`` distance band with ``0 <= lo <= hi``, as two floats."""
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (lo, hi) band with 0 <= lo <= hi, got {show(band)}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or hi < lo:
        raise ValueError(f"{name} must be a (lo, hi) band with 0 <= lo <= hi, got {show(band)}")
    return lo, hi


#: The ``goal_distance`` value that asks for goals anywhere in the free space.
UNIFORM_GOALS = "uniform"


def check_goal_distance(value: Any) -> Union[None, str, Tuple[float, float]]:
    """A ``goal_distance`` setting: ``None`` (the environment's default), ``"uniform"`` or a band."""
    if value is None or (isinstance(value, str) and value == UNIFORM_GOALS):
        return value
    if isinstance(value, str):
        raise ValueError(f"goal_distance must be None, {UNIFORM_GOALS!r} or a (lo, hi) band, got {value!r}")
    return check_band(value)


def check_action(action: Any, shape: Tuple[int, ...] = (2,)) -> np.ndarray:
    """Return ``action`` as a float64 array.

    Raises ``ValueError`` on a wrong shape, NaN or inf, complex numbers, or anything that is
    not numeric.
    """
    try:
        raw = np.asarray(action)
    except (TypeError, ValueError) as exc:  # e.g. ragged nested lists
        raise ValueError(f"action must be numeric with shape {shape}, got {show(action)}") from exc
    if raw.dtype.kind == "c":
        raise ValueError(f"action must be real, got complex numbers {show(action)}")
    try:
        a = raw.astype(np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"action must be numeric with shape {shape}, got {show(action)}") from exc
    if a.shape != shape:
        raise ValueError(f"action must have shape {shape}, got shape {a.shape}: {show(action)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {show(action)}")
    return a


def check_render_mode(render_mode: Optional[str], modes: Sequence[str]) -> Optional[str]:
    """``render_mode`` if it is ``None`` or one of ``modes``, else ``ValueError``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode must be one of {list(modes)} or None, got {show(render_mode)}")
    return render_mode


#: Constructor keywords that users sometimes pass to ``reset(options=...)`` by mistake.
CONSTRUCTOR_KEYWORDS = frozenset({
    "max_start_cost", "goal_threshold", "agent_radius", "cost_radius", "cost_fn", "boundary_cost",
    "action_noise", "substeps", "obs_type", "action_scale", "sensor_kwargs", "render_mode", "n_agents",
    "max_cycles", "min_separation", "collision_cost", "observe_neighbors", "max_episode_steps",
})


def parse_reset_options(options: Optional[Mapping], known: Iterable[str], env_name: str) -> Dict[str, Any]:
    """The ``reset`` options of the environments, with one rule for unknown keys.

    Args:
        options: what ``reset(options=...)`` received: ``None`` or a mapping.
        known: the keys the environment understands.
        env_name: the environment's class name, for messages.

    Returns:
        A new dict with the known keys only.

    Unknown keys are ignored with a ``UserWarning`` that names them (and says so when a key is
    a constructor argument rather than a reset option, or looks like a misspelt known key).
    They are not errors because PettingZoo's API test, and other generic tools, pass keys of
    their own. A value that is not a mapping raises ``ValueError``.
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"{env_name}.reset: options must be a dict or None, got {type(options).__name__}")
    known = tuple(known)
    unknown = sorted((k for k in options if k not in known), key=str)
    if unknown:
        hints = []
        for key in unknown:
            if key in CONSTRUCTOR_KEYWORDS:
                hints.append(f"{key!r} is a constructor argument (pass it to gymnasium.make or parallel_env)")
                continue
            close = difflib.get_close_matches(str(key), known, n=1)
            if close:
                hints.append(f"did you mean {close[0]!r} for {key!r}?")
        hint = ("; " + "; ".join(hints)) if hints else ""
        warnings.warn(
            f"ignoring unknown reset options {unknown} of {env_name}.reset; known: {list(known)}{hint}",
            UserWarning, stacklevel=3,
        )
    return {k: options[k] for k in known if k in options}


__all__ = [
    "CONSTRUCTOR_KEYWORDS",
    "check_action",
    "check_band",
    "check_count",
    "check_number",
    "check_render_mode",
    "parse_reset_options",
    "plural",
    "show",
    "show_point",
]
