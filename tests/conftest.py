"""Shared test helpers: a stand-in goal-conditioned agent for fast tests (no torch, no checkpoint),
and a runner of the example scripts.

Observations of the vector envs are positions divided by the world size; the stand-in's
"critics" are exact: distance = straight-line length in units (at least one step), cost = the
obstacle cost integrated along the straight segment. Its policy heads straight for the goal.
"""
from __future__ import annotations

import runpy
import struct
import sys
import zipfile

import numpy as np
import pytest

import safe_mapf_envs


class StraightLineAgent:
    def __init__(self, field, size):
        self.field = field
        self.size = np.asarray(size, dtype=np.float64)

    def _seg(self, a, b):
        a = np.asarray(a, np.float64) * self.size
        b = np.asarray(b, np.float64) * self.size
        length = np.linalg.norm(b - a, axis=-1)
        s = np.linspace(0.0, 1.0, 9)
        pts = a[..., None, :] + s[:, None] * (b - a)[..., None, :]
        cost = self.field.cost(pts).mean(axis=-1) * length
        blocked = self.field.inside(pts).any(axis=-1)  # through an obstacle: out of reach
        return np.where(blocked, 100.0, np.maximum(length, 1.0)), cost

    def pairwise(self, a, b, aggregate="max"):
        return self._seg(np.asarray(a)[:, None, :], np.asarray(b)[None, :, :])

    def pairwise_distance(self, a, b, aggregate="max", progress=None):
        return self.pairwise(a, b)[0]

    def pairwise_cost(self, a, b, aggregate="max", progress=None):
        return self.pairwise(a, b)[1]

    def distance(self, obs, goal, aggregate="max"):
        return self._seg(obs, goal)[0]

    def predict(self, batch, deterministic=True):
        d = (np.asarray(batch["desired_goal"]) - np.asarray(batch["observation"])) * self.size
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        return (d / np.maximum(n, 1.0)).astype(np.float32), None


@pytest.fixture(scope="session")
def stand_in_models():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1)
    agent = StraightLineAgent(env.field, env.world_size)
    env.close()
    return {"unconstrained": agent, "constrained": agent}


@pytest.fixture
def run_example(capsys):
    """``run_example(script, *argv)``: run ``python examples/<script> *argv`` in this process; returns
    its exit code and what it printed (``capsys.readouterr()``)."""

    def run(script, *argv):
        old, sys.argv = sys.argv, [script, *argv]
        try:
            with pytest.raises(SystemExit) as done:
                runpy.run_path(f"examples/{script}", run_name="__main__")
        finally:
            sys.argv = old
        return done.value.code, capsys.readouterr()

    return run


@pytest.fixture
def flip_byte():
    """``flip(src, dst, member)``: a copy of the zip archive ``src`` at ``dst`` with one bit flipped in the
    middle of ``member``'s compressed bytes (a corrupt file that still opens as a zip); returns ``dst``."""

    def flip(src, dst, member):
        raw = bytearray(src.read_bytes())
        info = zipfile.ZipFile(src).getinfo(member)
        n, m = struct.unpack("<HH", raw[info.header_offset + 26:info.header_offset + 30])
        raw[info.header_offset + 30 + n + m + info.compress_size // 2] ^= 0x40
        dst.write_bytes(bytes(raw))
        return dst

    return flip
