"""Self-sampling (the paper's Algorithm 1) and the problem reset wrapper."""
import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401
from agents.self_sampling import (
    OracleSampler,
    ProblemResetWrapper,
    SelfSampler,
    UniformSampler,
    make_sampler,
    observations_at,
)


class ChebyshevCritic:
    """Stands in for a model: distance = Chebyshev steps, cost = x coordinate, 3 members."""

    seed = 0

    def __init__(self, size=55.0):
        self.size = size
        self.policy = self
        self.calls = 0

    def values(self, obs, goals, quantities=("distance", "cost"), aggregate="none"):
        self.calls += 1
        d = np.abs(obs - goals).max(-1) * self.size
        members = np.stack([d - 0.5, d, d + 0.5])
        c = np.stack([obs[:, 0] * self.size] * 3)
        return {"distance": members, "cost": c}


@pytest.fixture
def env():
    return gym.make("SafeCentralObstacle-v0")


def test_keeps_the_k_pairs_closest_to_the_target(env):
    critic = ChebyshevCritic()
    sampler = SelfSampler(n_candidates=500, n_keep=20, target_distance=8.0, seed=1)
    sampler.bind(critic)
    problems = [sampler.reset_options(env) for _ in range(20)]
    assert sampler.n_refills == 1 and critic.calls == 1
    d = np.array([np.abs(p["start"] - p["goal"]).max() for p in problems])
    # candidate distances are spread over [0, 55]; the kept 20 of 500 lie close to 8
    assert np.all(np.abs(d - 8.0) < 2.0)
    # a 21st episode triggers a refill with fresh candidates
    sampler.reset_options(env)
    assert sampler.n_refills == 2 and critic.calls == 2
    assert sampler.stats["sampler/pred_distance"] == pytest.approx(8.0, abs=2.0)


def test_target_band_gives_a_diverse_set_and_cost_target_is_used(env):
    critic = ChebyshevCritic()
    sampler = SelfSampler(n_candidates=2000, n_keep=200, target_distance=(2.0, 20.0), seed=0)
    sampler.bind(critic)
    d = np.array([np.abs(p["start"] - p["goal"]).max() for p in (sampler.reset_options(env) for _ in range(200))])
    assert d.min() < 5.0 and d.max() > 17.0 and np.all(d < 23.0)
    costly = SelfSampler(n_candidates=2000, n_keep=50, target_distance=(2.0, 20.0), target_cost=50.0,
                         cost_fraction=1.0, seed=0)
    costly.bind(critic)
    starts = np.array([costly.reset_options(env)["start"] for _ in range(50)])
    assert np.median(starts[:, 0]) > 40.0  # the fake cost grows with x


def test_disagreement_bonus_prefers_uncertain_pairs(env):
    class Disagreeing(ChebyshevCritic):
        def values(self, obs, goals, quantities=("distance", "cost"), aggregate="none"):
            out = super().values(obs, goals, quantities, aggregate)
            spread = obs[:, 1] * 100.0  # members disagree more where y is large
            out["distance"] = np.stack([np.full(len(obs), 10.0) - spread, np.full(len(obs), 10.0) + spread])
            return out

    sampler = SelfSampler(n_candidates=400, n_keep=20, target_distance=10.0, disagreement_weight=10.0, seed=0)
    sampler.bind(Disagreeing())
    starts = np.array([sampler.reset_options(env)["start"] for _ in range(20)])
    assert starts[:, 1].mean() > 40.0


def test_unbound_sampler_draws_random_problems(env):
    sampler = SelfSampler(n_candidates=50, n_keep=5, seed=3)
    p = sampler.reset_options(env)
    u = env.unwrapped
    assert u.scenario.is_free(p["start"]) and u.scenario.is_free(p["goal"])


def test_wrapper_applies_the_sampler_unless_options_are_given(env):
    sampler = SelfSampler(n_candidates=100, n_keep=10, target_distance=5.0, seed=0)
    sampler.bind(ChebyshevCritic())
    wrapped = ProblemResetWrapper(env, sampler)
    obs, info = wrapped.reset(seed=0)
    assert np.abs(info["position"] - info["goal"]).max() == pytest.approx(5.0, abs=2.0)
    obs, info = wrapped.reset(options={"start": (2.0, 2.0), "goal": (50.0, 50.0)})
    np.testing.assert_allclose(info["position"], (2.0, 2.0))
    assert ProblemResetWrapper(env).reset(seed=0)[0]["observation"].shape == (2,)


def test_oracle_and_uniform_options():
    assert OracleSampler((1.0, 4.0)).reset_options(None) == {"goal_distance": (1.0, 4.0)}
    assert isinstance(make_sampler("oracle", band=(1, 2)), OracleSampler)


def test_observations_at_uses_the_env_observation(env):
    pos = np.array([[5.5, 11.0], [27.5, 0.0]])
    np.testing.assert_allclose(observations_at(env, pos), pos / 55.0, rtol=1e-6)


@pytest.mark.parametrize("kwargs, match", [
    ({"n_keep": 0}, "n_keep"), ({"n_candidates": 5, "n_keep": 10}, "n_keep"),
    ({"target_distance": (5.0, 1.0)}, "target_distance"), ({"target_cost": -1.0}, "target_cost"),
    ({"disagreement_weight": -1.0}, "disagreement_weight")])
def test_invalid_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SelfSampler(**kwargs)


def test_unknown_sampler_name():
    with pytest.raises(ValueError, match="problem sampler"):
        make_sampler("psychic")


def test_cost_fraction_splits_the_kept_problems(env):
    sampler = SelfSampler(n_candidates=2000, n_keep=40, target_distance=(2.0, 20.0), target_cost=50.0,
                          cost_fraction=0.25, seed=0)
    sampler.bind(ChebyshevCritic())
    starts = np.array([sampler.reset_options(env)["start"] for _ in range(40)])
    assert np.sum(starts[:, 0] > 45.0) >= 10  # the 10 cost-targeted ones, x near 50
    assert np.sum(starts[:, 0] < 30.0) >= 15  # the distance-only ones are spread over the map


def test_the_uniform_training_sampler_keeps_asking_for_goals_anywhere():
    env = gym.make("SafeCentralObstacle-v0")
    assert UniformSampler().reset_options(env) == {"goal_distance": "uniform"}
    assert UniformSampler().reset_options(gym.make("Pendulum-v1")) is None


DOOR = ("....#....",
        "....#....",
        ".........",
        "....#....",
        "....#....")


def door_env():
    """Two small rooms joined by a one-cell door (fast to sample on: few boxes)."""
    from safe_mapf_envs.maps import GridMap

    return gym.make("SafeFourRooms-v0", layout=GridMap("Door", DOOR, resize_factor=2.0, cost_radius=1.0))


def _clearance(env, points):
    """Distance to the nearest obstacle or the world's border."""
    sc = env.unwrapped.scenario
    p = np.asarray(points, dtype=np.float64)
    border = np.minimum(p, sc.size_arr - p).min(-1)
    return np.minimum(sc.field.distance(p), border)


def test_narrow_states_lie_in_passages_and_reach_doorways():
    env = door_env()
    u = env.unwrapped
    rng = np.random.default_rng(0)
    narrow = u.sample_narrow_states(400, rng)
    uniform = u.sample_states(400, rng)
    r = u.scenario.agent_radius
    assert u.scenario.is_free(narrow).all()
    # an end of the bridge is blocked, so the centre is at most half a bridge plus a radius from an obstacle
    assert (_clearance(env, narrow) <= 2.5 * r + r + 1e-9).all()
    assert np.median(_clearance(env, narrow)) < 0.5 * np.median(_clearance(env, uniform))


@pytest.mark.parametrize("bridge", [0.0, -1.0, float("nan")])
def test_narrow_states_reject_a_bad_bridge(bridge):
    env = door_env()
    with pytest.raises(ValueError, match="bridge"):
        env.unwrapped.sample_narrow_states(5, np.random.default_rng(0), bridge=bridge)


def test_narrow_crossings_go_through_a_passage_along_a_free_segment():
    env = door_env()
    sc = env.unwrapped.scenario
    starts, goals = env.unwrapped.sample_narrow_crossings(60, (2.0, 5.0), np.random.default_rng(1))
    t = np.linspace(0.0, 1.0, 41)[None, :, None]
    path = starts[:, None, :] + t * (goals - starts)[:, None, :]
    assert sc.is_free(starts).all() and sc.is_free(goals).all()
    length = np.linalg.norm(goals - starts, axis=1)
    # the way through is about the straight segment (free where the sampler checked it)
    geodesic = np.array([env.unwrapped.geodesic_distance(a, b) for a, b in zip(starts, goals)])
    assert (geodesic <= 1.1 * length + 0.5).all()
    assert ((length >= 4.0 - 1e-9) & (length <= 10.0 + 1e-9)).all()
    # somewhere along the way the passage is narrow, while the ends lie farther from obstacles
    narrowest = _clearance(env, path.reshape(-1, 2)).reshape(len(starts), -1).min(axis=1)
    assert (narrowest <= 3.5 * sc.agent_radius + 1e-9).all()


def test_narrow_fraction_adds_unscored_passage_crossings():
    env = door_env()
    critic = ChebyshevCritic()
    only = SelfSampler(n_candidates=200, n_keep=20, narrow_fraction=1.0, seed=0)
    only.bind(critic)
    pairs = [only.reset_options(env) for _ in range(20)]
    assert critic.calls == 0  # the crossings are not scored
    gaps = np.array([np.linalg.norm(p["goal"] - p["start"]) for p in pairs])
    assert ((gaps >= 4 * env.unwrapped.action_scale - 1e-9) & (gaps <= 12 * env.unwrapped.action_scale + 1e-9)).all()
    half = SelfSampler(n_candidates=200, n_keep=20, narrow_fraction=0.5, target_distance=1.0, seed=0)
    half.bind(critic)
    gaps = np.array([np.linalg.norm(p["goal"] - p["start"]) for p in (half.reset_options(env) for _ in range(20))])
    assert critic.calls == 1
    assert np.sum(gaps >= 4 * env.unwrapped.action_scale - 1e-9) >= 10  # the crossings, besides 10 scored short ones
    with pytest.raises(ValueError, match="narrow_fraction"):
        SelfSampler(narrow_fraction=1.5)
