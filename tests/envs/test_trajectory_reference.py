"""Seeded trajectories stay what they were: the same observations, rewards, costs, contacts and
episode ends for the same seeds and actions, in the single-agent, multi-agent and native vector envs.

``tests/envs/data/trajectory_reference.npz`` holds the trajectories of :func:`record`, computed
once; regenerate it (only after a change meant to alter behaviour) with
``python tests/envs/test_trajectory_reference.py``.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Dict, List

import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs

REFERENCE = Path(__file__).parent / "data" / "trajectory_reference.npz"


def _stack(rows: List[Dict[str, np.ndarray]]) -> Dict[str, np.ndarray]:
    return {k: np.stack([np.asarray(r[k], dtype=np.float64) for r in rows]) for k in rows[0]}


def _toward(position: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Unit steps from ``position`` towards ``goal`` (rows)."""
    d = goal - position
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)


def _single(env_id: str, seed: int, steps: int, greedy: float = 0.0, **kwargs) -> Dict[str, np.ndarray]:
    """``steps`` random-action steps of ``gym.make(env_id)`` (plus ``greedy`` times a unit step
    towards the goal), reset (unseeded) as episodes end."""
    env = gym.make(env_id, **kwargs)
    actions = np.random.default_rng(seed + 100).uniform(-1.2, 1.2, size=(steps, 2)).astype(np.float32)
    rows = []

    def row(obs, reward, terminated, truncated, info, reset):
        r = {"observation": obs["observation"], "achieved_goal": obs["achieved_goal"],
             "desired_goal": obs["desired_goal"], "reward": reward, "terminated": terminated,
             "truncated": truncated, "cost": info["cost"], "position": info["position"], "goal": info["goal"],
             "distance_to_goal": info["distance_to_goal"], "is_success": info["is_success"], "reset": reset}
        if "parked" in info:
            parked = np.full((4, 2), np.nan)
            parked[:len(info["parked"])] = info["parked"]
            r["parked"] = parked
        return r

    obs, info = env.reset(seed=seed)
    rows.append(row(obs, 0.0, False, False, info, True))
    for a in actions:
        if greedy:
            a = (a + greedy * _toward(info["position"], info["goal"])).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(a)
        rows.append(row(obs, reward, terminated, truncated, info, False))
        if terminated or truncated:
            obs, info = env.reset()
            rows.append(row(obs, 0.0, False, False, info, True))
    env.close()
    return _stack(rows)


def _parallel(env_id: str, n: int, seed: int, steps: int, greedy: float = 0.0, **kwargs) -> Dict[str, np.ndarray]:
    """``steps`` random-action steps of the parallel env (plus ``greedy`` times a unit step
    towards each goal), every agent's values per step (NaN for agents not reported), reset
    (unseeded) when every agent is done."""
    env = safe_mapf_envs.parallel_env(env_id, n_agents=n, **kwargs)
    names = env.possible_agents
    rng = np.random.default_rng(seed + 200)
    rows = []
    k = env.observe_neighbors

    def row(obs, rewards, terms, truncs, infos, reset):
        r: Dict[str, np.ndarray] = {
            "observation": np.full((n, 2), np.nan), "desired_goal": np.full((n, 2), np.nan),
            "neighbors": np.full((n, max(k, 1), 2), np.nan), "reward": np.full(n, np.nan),
            "terminated": np.full(n, np.nan), "truncated": np.full(n, np.nan), "cost": np.full(n, np.nan),
            "obstacle_cost": np.full(n, np.nan), "collisions": np.full(n, np.nan),
            "collided_with": np.zeros((n, n)), "position": np.full((n, 2), np.nan),
            "distance_to_goal": np.full(n, np.nan), "is_success": np.full(n, np.nan),
            "all_positions": env.positions, "goals": env.goals, "parked": env.parked, "reset": reset,
        }
        for i, a in enumerate(names):
            if a in obs:
                r["observation"][i] = obs[a]["observation"]
                assert np.array_equal(obs[a]["achieved_goal"], obs[a]["observation"])
                r["desired_goal"][i] = obs[a]["desired_goal"]
                if k:
                    r["neighbors"][i] = obs[a]["neighbors"]
            if a in rewards:
                r["reward"][i] = rewards[a]
                r["terminated"][i] = terms[a]
                r["truncated"][i] = truncs[a]
            if a in infos:
                inf = infos[a]
                r["cost"][i] = inf["cost"]
                r["obstacle_cost"][i] = inf["obstacle_cost"]
                r["collisions"][i] = inf["collisions"]
                for other in inf["collided_with"]:
                    r["collided_with"][i, env.agent_name_mapping[other]] = 1.0
                r["position"][i] = inf["position"]
                r["distance_to_goal"][i] = inf["distance_to_goal"]
                r["is_success"][i] = inf["is_success"]
        return r

    obs, infos = env.reset(seed=seed)
    rows.append(row(obs, {}, {}, {}, infos, True))
    for _ in range(steps):
        if not env.agents:
            obs, infos = env.reset()
            rows.append(row(obs, {}, {}, {}, infos, True))
            continue
        acts = {a: rng.uniform(-1.2, 1.2, 2).astype(np.float32) for a in env.agents}
        if greedy:
            toward = greedy * _toward(env.positions, env.goals)
            acts = {a: (v + toward[env.agent_name_mapping[a]]).astype(np.float32) for a, v in acts.items()}
        obs, rewards, terms, truncs, infos = env.step(acts)
        rows.append(row(obs, rewards, terms, truncs, infos, False))
    env.close()
    return _stack(rows)


def _vector(env_id: str, n: int, seed: int, steps: int) -> Dict[str, np.ndarray]:
    """``steps`` random-action steps of the native vector env (next-step autoreset)."""
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    actions = np.random.default_rng(seed + 300).uniform(-1.2, 1.2, size=(steps, n, 2)).astype(np.float32)
    rows = []
    obs, info = env.reset(seed=seed)
    zero = np.zeros(n)
    rows.append({"observation": obs["observation"], "desired_goal": obs["desired_goal"], "reward": zero,
                 "terminated": zero, "truncated": zero, "cost": info["cost"], "position": info["position"]})
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        rows.append({"observation": obs["observation"], "desired_goal": obs["desired_goal"], "reward": reward,
                     "terminated": terminated, "truncated": truncated, "cost": info["cost"],
                     "position": info["position"]})
    env.close()
    return _stack(rows)


#: name -> (function, arguments, keyword arguments)
CASES = {
    "central_obstacle": (_single, ("SafeCentralObstacle-v0", 0, 150), {}),
    "center_dot": (_single, ("SafeCenterDot-v0", 1, 150), {}),
    "four_rooms_noise": (_single, ("SafeFourRooms-v0", 2, 100), {"action_noise": 0.2}),
    "central_obstacle_parked": (_single, ("SafeCentralObstacle-v0", 3, 120), {"parked_agents": 4}),
    "central_obstacle_uniform_goal": (_single, ("SafeCentralObstacle-v0", 4, 60),
                                      {"goal_distance": "uniform", "max_episode_steps": 30}),
    "central_obstacle_greedy": (_single, ("SafeCentralObstacle-v0", 5, 150), {"greedy": 1.0}),
    "center_dot_greedy_parked": (_single, ("SafeCenterDot-v0", 6, 150),
                                 {"greedy": 1.0, "parked_agents": 3, "parked_fraction": 0.5}),
    "multi_20_greedy": (_parallel, ("SafeCentralObstacle-v0", 20, 6, 150),
                        {"greedy": 1.0, "max_cycles": 70, "goal_distance": (0.0, 30.0)}),
    "multi_30_greedy_crowd": (_parallel, ("SafeCenterDot-v0", 30, 7, 100),
                              {"greedy": 1.0, "max_cycles": 50, "collision_cost": 0.25}),
    "multi_10": (_parallel, ("SafeCentralObstacle-v0", 10, 0, 160), {"max_cycles": 60}),
    "multi_10_neighbors_cost": (_parallel, ("SafeCenterDot-v0", 10, 1, 80),
                                {"max_cycles": 40, "observe_neighbors": 3, "collision_cost": 0.5,
                                 "action_noise": 0.1}),
    "multi_10_pass_through": (_parallel, ("SafeCentralObstacle-v0", 10, 2, 60),
                              {"max_cycles": 30, "agent_collisions": False}),
    "multi_crowd": (_parallel, ("SafeCenterDot-v0", 40, 3, 50),
                    {"max_cycles": 25, "min_separation": 1.0, "collision_cost": 1.0}),
    "multi_1": (_parallel, ("SafeCentralObstacle-v0", 1, 4, 40), {"max_cycles": 15}),
    "multi_3": (_parallel, ("SafeFourRooms-v0", 3, 5, 40), {"max_cycles": 15}),
    "vector_8": (_vector, ("SafeCentralObstacle-v0", 8, 0, 60), {}),
}


def record() -> Dict[str, np.ndarray]:
    """Every case of :data:`CASES`, flattened into ``{"case/field": array}``."""
    out: Dict[str, np.ndarray] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, (fn, args, kwargs) in CASES.items():
            for key, value in fn(*args, **kwargs).items():  # type: ignore[operator]
                out[f"{name}/{key}"] = value
    return out


@pytest.fixture(scope="module")
def reference():
    with np.load(REFERENCE) as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize("case", sorted(CASES))
def test_trajectory_matches_the_reference(reference, case):
    fn, args, kwargs = CASES[case]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = fn(*args, **kwargs)  # type: ignore[operator]
    expected = {k.split("/", 1)[1]: v for k, v in reference.items() if k.startswith(case + "/")}
    assert sorted(got) == sorted(expected)
    for key, want in expected.items():
        assert got[key].shape == want.shape, f"{case}/{key}: shape {got[key].shape} != {want.shape}"
        np.testing.assert_allclose(got[key], want, rtol=0, atol=1e-9, equal_nan=True, err_msg=f"{case}/{key}")


if __name__ == "__main__":
    if "--check" not in sys.argv:
        REFERENCE.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(REFERENCE, **record())
        print(f"wrote {REFERENCE}")
