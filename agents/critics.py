"""Ensembles of categorical critics: the distance critic (steps to the goal) and the cost critic
(cumulative cost) of the safe agent are both a :class:`CategoricalCritic` over their own support."""
from __future__ import annotations

from typing import Optional, Sequence, Type

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

from .encoders import GoalPairExtractor
from .heads import EnsembleHead


class CategoricalCritic(BaseModel):
    """An ensemble of categorical Q-functions ``Z(obs, action, goal)`` over a fixed support.

    ``forward`` returns logits of shape ``(n_members, B, n_bins)``; :meth:`expected` turns
    logits into the expected value per member (distance in steps, or cumulative cost).
    """

    features_extractor: GoalPairExtractor
    optimizer: th.optim.Optimizer
    support: th.Tensor

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, net_arch: Sequence[int],
                 features_extractor: GoalPairExtractor, features_dim: int, support: th.Tensor,
                 n_members: int = 3, activation_fn: Type[nn.Module] = nn.ReLU,
                 normalize_images: bool = False) -> None:
        super().__init__(observation_space, action_space, features_extractor=features_extractor,
                         normalize_images=normalize_images)
        self.action_dim = int(np.prod(action_space.shape))
        self.n_members = n_members
        self.head = EnsembleHead(n_members, features_dim + self.action_dim, net_arch, len(support), activation_fn)
        self.register_buffer("support", support.clone().float())

    def extract_features(self, obs: PyTorchObs,
                         features_extractor: Optional[BaseFeaturesExtractor] = None) -> th.Tensor:
        return (features_extractor or self.features_extractor)(obs)

    def logits_from_features(self, features: th.Tensor, actions: th.Tensor) -> th.Tensor:
        return self.head(th.cat([features, actions], dim=1))

    def forward(self, obs: PyTorchObs, actions: th.Tensor) -> th.Tensor:
        return self.logits_from_features(self.extract_features(obs), actions)

    def expected(self, logits: th.Tensor) -> th.Tensor:
        """Expected value of each member's distribution: ``(..., K) -> (...)``."""
        return th.softmax(logits, dim=-1) @ self.support


__all__ = ["CategoricalCritic"]
