"""Networks: pairwise matrices agree with elementwise values; the panorama encoder."""
import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces

import safe_mapf_envs  # noqa: F401
from agents.encoders import GoalPairExtractor, PanoramaEncoder
from agents.policies import SafeGoalPolicy


def const_lr(_):
    return 1e-3


@pytest.fixture(scope="module")
def vector_policy():
    th.manual_seed(0)
    env = gym.make("SafeCentralObstacle-v0")
    return SafeGoalPolicy(env.observation_space, env.action_space, const_lr, net_arch=[32, 32],
                          features_extractor_kwargs={"net_arch": [16]})


def panorama_space():
    img = spaces.Box(0, 255, (4, 32, 32, 4), np.uint8)
    return spaces.Dict({"observation": img, "achieved_goal": img, "desired_goal": img})


def test_pairwise_matches_elementwise(vector_policy):
    rng = np.random.default_rng(0)
    a = rng.random((7, 2), dtype=np.float32)
    b = rng.random((5, 2), dtype=np.float32)
    ii, jj = np.meshgrid(np.arange(7), np.arange(5), indexing="ij")
    for aggregate in ("max", "mean", "min"):
        pair = vector_policy.pairwise(a, b, aggregate=aggregate)
        elem = vector_policy.values(a[ii.ravel()], b[jj.ravel()], aggregate=aggregate)
        for q in ("distance", "cost"):
            assert pair[q].shape == (7, 5) and pair[q].dtype == np.float32
            np.testing.assert_allclose(pair[q], elem[q].reshape(7, 5), rtol=1e-4, atol=1e-4)
    full = vector_policy.pairwise(a, b, aggregate="none")
    assert full["distance"].shape == (3, 7, 5)
    np.testing.assert_allclose(full["distance"].max(0), vector_policy.pairwise(a, b)["distance"], atol=1e-5)


@pytest.mark.parametrize("chunk_size", [1, 3, 6, 1000])
def test_pairwise_chunking_does_not_change_results(vector_policy, chunk_size):
    rng = np.random.default_rng(1)
    a = rng.random((9, 2), dtype=np.float32)
    b = rng.random((8, 2), dtype=np.float32)
    ref = vector_policy.pairwise(a, b, chunk_size=1 << 20)
    got = vector_policy.pairwise(a, b, chunk_size=chunk_size)
    for q in ("distance", "cost"):
        np.testing.assert_allclose(got[q], ref[q], rtol=1e-5, atol=1e-5)


def test_empty_inputs_give_empty_matrices(vector_policy):
    out = vector_policy.pairwise(np.zeros((0, 2), np.float32), np.zeros((4, 2), np.float32))
    assert out["distance"].shape == (0, 4) and out["cost"].shape == (0, 4)


def test_value_ranges_follow_the_supports(vector_policy):
    rng = np.random.default_rng(2)
    a = rng.random((20, 2), dtype=np.float32)
    out = vector_policy.pairwise(a, a)
    assert np.all((out["distance"] >= 1.0) & (out["distance"] <= 20.0))
    assert np.all((out["cost"] >= 0.0) & (out["cost"] <= 40.0))


def test_single_pair_and_bad_inputs(vector_policy):
    d = vector_policy.values(np.array([0.1, 0.2], np.float32), np.array([0.3, 0.4], np.float32))["distance"]
    assert np.ndim(d) == 0
    with pytest.raises(ValueError, match="shape"):
        vector_policy.values(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="same length"):
        vector_policy.values(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="aggregate"):
        vector_policy.pairwise(np.zeros((3, 2)), np.zeros((3, 2)), aggregate="median")
    with pytest.raises(ValueError, match="quantities"):
        vector_policy.pairwise(np.zeros((3, 2)), np.zeros((3, 2)), quantities=("speed",))
    with pytest.raises(ValueError, match="NaN"):
        vector_policy.values(np.full((1, 2), np.nan), np.zeros((1, 2)))


def test_panorama_extractor_is_the_papers_cnn():
    space = panorama_space()
    fe = GoalPairExtractor(space)
    assert isinstance(fe.encoder, PanoramaEncoder)
    convs = [m for m in fe.encoder.cnn if isinstance(m, th.nn.Conv2d)]
    assert [(c.in_channels, c.out_channels, c.kernel_size, c.stride) for c in convs] == [
        (4, 16, (8, 8), (4, 4)), (16, 32, (4, 4), (4, 4))]
    assert fe.encoder.fc[0].out_features == 256
    assert fe.features_dim == 512
    obs = {k: th.randint(0, 256, (3, 4, 32, 32, 4), dtype=th.uint8) for k in space.spaces}
    feats = fe(obs)
    assert feats.shape == (3, 512)
    # observation and goal go through the same network
    th.testing.assert_close(feats[:, :256], fe.encode(obs["observation"]))
    th.testing.assert_close(feats[:, 256:], fe.encode(obs["desired_goal"]))


def test_panorama_policy_predicts_and_builds_matrices():
    th.manual_seed(0)
    space = panorama_space()
    policy = SafeGoalPolicy(space, spaces.Box(-1, 1, (2,), np.float32), const_lr, net_arch=[16, 16],
                            features_extractor_kwargs={"features_dim": 32})
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 256, (5, 4, 32, 32, 4), dtype=np.uint8)
    actions, _ = policy.predict({"observation": imgs, "achieved_goal": imgs, "desired_goal": imgs[::-1].copy()})
    assert actions.shape == (5, 2) and np.all(np.abs(actions) <= 1)
    pair = policy.pairwise(imgs[:3], imgs[2:], chunk_size=4)
    elem = policy.values(np.repeat(imgs[:3], 3, 0), np.tile(imgs[2:], (3, 1, 1, 1, 1)))
    np.testing.assert_allclose(pair["distance"], elem["distance"].reshape(3, 3), rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(pair["cost"], elem["cost"].reshape(3, 3), rtol=1e-4, atol=1e-4)


def test_extractor_rejects_mismatched_goal_space():
    bad = spaces.Dict({"observation": spaces.Box(0, 1, (2,)), "achieved_goal": spaces.Box(0, 1, (3,)),
                       "desired_goal": spaces.Box(0, 1, (3,))})
    with pytest.raises(ValueError, match="same shape"):
        GoalPairExtractor(bad)
    with pytest.raises(ValueError, match="encoder"):
        GoalPairExtractor(panorama_space(), encoder="transformer")


@pytest.mark.parametrize("chunk_size", [1, 7, 1 << 20])
def test_pairwise_within_is_exact_below_the_cutoff_and_a_lower_bound_beyond(vector_policy, chunk_size):
    rng = np.random.default_rng(4)
    a = rng.random((30, 2), dtype=np.float32)
    b = rng.random((11, 2), dtype=np.float32)
    full = vector_policy.pairwise(a, b)
    within = float(np.median(full["distance"]))  # half the pairs on either side
    got = vector_policy.pairwise(a, b, chunk_size=chunk_size, within=within)
    near = full["distance"] < within
    assert 0 < near.sum() < near.size
    np.testing.assert_array_equal(got["distance"] < within, near)
    for q in ("distance", "cost"):
        np.testing.assert_allclose(got[q][near], full[q][near], rtol=1e-5, atol=1e-5)
    # beyond the cut-off: the first member's distance where it is already past the cut-off (a
    # lower bound of the maximum) and no cost; the exact values where only the maximum is past it
    first = vector_policy.pairwise(a, b, aggregate="none")["distance"][0]
    screened = first >= within
    assert not (screened & near).any() and screened.any() and (~screened & ~near).any()
    np.testing.assert_allclose(got["distance"][screened], first[screened], rtol=1e-5, atol=1e-5)
    assert np.all(np.isinf(got["cost"][screened]))
    for q in ("distance", "cost"):
        np.testing.assert_allclose(got[q][~screened], full[q][~screened], rtol=1e-5, atol=1e-5)


def test_pairwise_within_needs_the_maximum_of_the_distances(vector_policy):
    x = np.zeros((3, 2), np.float32)
    with pytest.raises(ValueError, match="within needs aggregate='max'"):
        vector_policy.pairwise(x, x, aggregate="mean", within=3.0)
    with pytest.raises(ValueError, match="within needs"):
        vector_policy.pairwise(x, x, quantities=("cost",), within=3.0)


@pytest.mark.parametrize("chunk_size", [1, 5, 8192])
def test_pairwise_at_scores_the_listed_pairs_as_pairwise_does(vector_policy, chunk_size):
    rng = np.random.default_rng(5)
    a = rng.random((13, 2), dtype=np.float32)
    b = rng.random((9, 2), dtype=np.float32)
    rows, cols = rng.integers(0, 13, 40), rng.integers(0, 9, 40)
    full = vector_policy.pairwise(a, b)
    got = vector_policy.pairwise_at(a, b, rows, cols, chunk_size=chunk_size)
    for q in ("distance", "cost"):
        assert got[q].shape == (40,) and got[q].dtype == np.float32
        np.testing.assert_allclose(got[q], full[q][rows, cols], rtol=1e-5, atol=1e-5)
    within = float(np.median(full["distance"]))
    screened = vector_policy.pairwise(a, b, within=within)
    near = vector_policy.pairwise_at(a, b, rows, cols, chunk_size=chunk_size, within=within)
    for q in ("distance", "cost"):  # the same values as pairwise's, infinite costs included
        np.testing.assert_allclose(near[q], screened[q][rows, cols], rtol=1e-5, atol=1e-5)
    assert vector_policy.pairwise_at(a, b, [], [])["distance"].shape == (0,)
    with pytest.raises(ValueError, match="out of range"):
        vector_policy.pairwise_at(a, b, [13], [0])
    with pytest.raises(ValueError, match="same length"):
        vector_policy.pairwise_at(a, b, [1, 2], [0])
