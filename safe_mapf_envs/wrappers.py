"""Wrappers around the navigation environments."""
from __future__ import annotations

import gymnasium as gym


class SafetyGymnasiumStyle(gym.Wrapper):
    """Return the cost as its own value, as Safety-Gymnasium does.

    ``step`` returns ``(obs, reward, cost, terminated, truncated, info)`` with
    ``cost = info["cost"]``; ``info`` keeps the cost too.
    """

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, float(info["cost"]), terminated, truncated, info


__all__ = ["SafetyGymnasiumStyle"]
