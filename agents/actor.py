"""The deterministic goal-conditioned actor of the safe agent."""
from __future__ import annotations

from typing import Any, Dict, Optional, Sequence, Type

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

from .encoders import GoalPairExtractor
from .heads import EnsembleHead


class GoalActor(BasePolicy):
    """Deterministic goal-conditioned actor ``pi(obs, goal) -> action in [-1, 1]^A``.

    ``input_norm`` puts a LayerNorm on the features before the MLP (after the actor trunk of
    DrQ-v2): features of a shared image encoder, trained by the critics alone, grow in scale,
    and an actor fed them directly drives ``tanh`` into saturation, where it stops learning.
    The observation's and the goal's codes (the two halves of the features) are normalised
    separately by one LayerNorm, so the first layer stays linear in each code and the
    planner's pairwise matrices keep their one-encoding-per-node shortcut.
    """

    features_extractor: GoalPairExtractor
    optimizer: th.optim.Optimizer

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, net_arch: Sequence[int],
                 features_extractor: GoalPairExtractor, features_dim: int,
                 activation_fn: Type[nn.Module] = nn.ReLU, normalize_images: bool = False,
                 input_norm: bool = False) -> None:
        super().__init__(observation_space, action_space, features_extractor=features_extractor,
                         normalize_images=normalize_images, squash_output=True)
        self.net_arch = list(net_arch)
        self.features_dim = features_dim
        self.activation_fn = activation_fn
        self.action_dim = int(np.prod(action_space.shape))
        self.input_norm = bool(input_norm)
        if self.input_norm and features_dim % 2:
            raise ValueError(f"input_norm needs features made of two codes of equal size, got {features_dim}")
        self.norm = nn.LayerNorm(features_dim // 2) if self.input_norm else nn.Identity()
        self.mu = EnsembleHead(1, features_dim, net_arch, self.action_dim, activation_fn)

    def _get_constructor_parameters(self) -> Dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(dict(net_arch=self.net_arch, features_dim=self.features_dim, activation_fn=self.activation_fn,
                         features_extractor=self.features_extractor, input_norm=self.input_norm))
        return data

    def extract_features(self, obs: PyTorchObs,
                         features_extractor: Optional[BaseFeaturesExtractor] = None) -> th.Tensor:
        return (features_extractor or self.features_extractor)(obs)

    def normalize_features(self, features: th.Tensor) -> th.Tensor:
        """The MLP's input: ``[norm(code(obs)), norm(code(goal))]`` (identity without ``input_norm``)."""
        if not self.input_norm:
            return features
        return self.norm(features.unflatten(-1, (2, -1))).flatten(-2)

    def preactivation(self, features: th.Tensor) -> th.Tensor:
        """The action before ``tanh``."""
        return self.mu(self.normalize_features(features))[0]

    def action_from_features(self, features: th.Tensor) -> th.Tensor:
        return th.tanh(self.preactivation(features))

    def forward(self, obs: PyTorchObs) -> th.Tensor:
        return self.action_from_features(self.extract_features(obs))

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self(observation)


__all__ = ["GoalActor"]
