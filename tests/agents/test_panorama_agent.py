"""Panorama agents: the fast encoder, the shared-encoder layout, save/load, learning from images."""
import gymnasium as gym
import numpy as np
import pytest
import torch as th
from scipy.stats import spearmanr
from stable_baselines3.common.logger import configure

import safe_mapf_envs  # noqa: F401
from agents import SafeGoalTD3
from agents.augmentation import RandomShift
from agents.encoders import PanoramaEncoder
from agents.evaluation import sample_problems
from agents.self_sampling import observations_at

th.set_num_threads(1)

ENV = "SafeApartment0-v0"


@pytest.mark.parametrize("shape, layers", [
    ((4, 32, 32, 4), ((16, 8, 4), (32, 4, 4))),   # the paper's: reads the top-left 20 x 20 pixels
    ((4, 32, 32, 4), ((16, 8, 4), (32, 3, 2))),   # reads everything
    ((32, 32, 3), ((8, 4, 2), (16, 3, 1), (8, 2, 2))),
    ((2, 24, 20, 4), ((16, 8, 4), (32, 4, 4))),
])
def test_fast_encoder_equals_a_plain_conv_stack(shape, layers):
    th.manual_seed(0)
    enc = PanoramaEncoder(shape, features_dim=32, conv_layers=layers)
    x = th.randint(0, 256, (6, *shape), dtype=th.uint8)
    assert th.allclose(enc(x), enc.reference_forward(x), atol=1e-5)
    encf = PanoramaEncoder(shape, features_dim=32, conv_layers=layers, scale=1.0)
    xf = th.rand(6, *shape)
    assert th.allclose(encf(xf), encf.reference_forward(xf), atol=1e-5)
    # gradients agree too
    g1 = th.autograd.grad(encf(xf).square().sum(), list(encf.parameters()))
    g2 = th.autograd.grad(encf.reference_forward(xf).square().sum(), list(encf.parameters()))
    for a, b in zip(g1, g2):
        assert th.allclose(a, b, atol=1e-4)


def test_paper_encoder_reads_only_its_receptive_field():
    enc = PanoramaEncoder((4, 32, 32, 4))
    assert enc.read_size == (20, 20)
    x = th.randint(0, 256, (2, 4, 32, 32, 4), dtype=th.uint8)
    y = x.clone()
    y[:, :, 20:, :, :] = 0
    y[:, :, :, 20:, :] = 255
    assert th.equal(enc(x), enc(y))


def model_on(env_id=ENV, **kw):
    args = dict(learning_starts=100, batch_size=16, seed=0, device="cpu", problem_sampler="uniform",
                policy_kwargs=dict(net_arch=[32, 32], features_extractor_kwargs={"features_dim": 64}),
                replay_buffer_kwargs=dict(achieved_goal_is_observation=True))
    args.update(kw)
    return SafeGoalTD3("MultiInputPolicy", env_id, **args)


@pytest.fixture(scope="module")
def small():
    model = model_on()
    model.set_logger(configure(None, []))
    model.learn(200)
    return model


def test_images_get_one_shared_encoder_and_a_polyak_target(small):
    p = small.policy
    assert p.share_encoder
    assert p.actor.features_extractor is p.encoder
    assert p.critic.features_extractor is p.encoder and p.cost_critic.features_extractor is p.encoder
    for t in (p.actor_target, p.critic_target, p.cost_critic_target):
        assert t.features_extractor is p.encoder_target
    online, target = p.target_parameter_pairs()
    assert len({id(x) for x in online}) == len(online) and len(online) == len(target)
    n_enc = len(list(p.encoder.parameters()))
    assert sum(any(x is q for q in p.encoder.parameters()) for x in online) == n_enc
    # the encoder is in the distance critic's optimiser only; the actor's holds its head alone
    enc_ids = {id(x) for x in p.encoder.parameters()}
    groups = lambda opt: {id(x) for g in opt.param_groups for x in g["params"]}  # noqa: E731
    assert enc_ids <= groups(p.critic.optimizer)
    assert not enc_ids & groups(p.actor.optimizer) and not enc_ids & groups(p.cost_critic.optimizer)
    # vectors keep an extractor per network
    v = model_on("SafeCenterDot-v0", replay_buffer_kwargs={}).policy
    assert not v.share_encoder and v.actor.features_extractor is not v.critic.features_extractor


def test_actor_loss_leaves_the_encoder_untouched(small):
    p = small.policy
    data = small.replay_buffer.sample(16)
    before_enc = [x.detach().clone() for x in p.encoder.parameters()]
    before_mu = [x.detach().clone() for x in p.actor.mu.parameters()]
    with th.no_grad():
        o, g = data.observations["observation"], data.observations["desired_goal"]
        feats = th.cat(p.encoder.encode(th.cat([o, g])).split([16, 16]), 1)
    small._actor_step(feats, feats, feats, lam=0.5)
    assert all(th.equal(a, b) for a, b in zip(before_enc, p.encoder.parameters()))
    assert any(not th.equal(a, b) for a, b in zip(before_mu, p.actor.mu.parameters()))
    # a full update trains the encoder through the critic losses and moves the target towards it
    before_t = [x.detach().clone() for x in p.encoder_target.parameters()]
    small.target_update_interval = 1
    small.train(1, 16)
    assert any(not th.equal(a, b) for a, b in zip(before_enc, p.encoder.parameters()))
    assert any(not th.equal(a, b) for a, b in zip(before_t, p.encoder_target.parameters()))


def test_shared_encoder_save_load_round_trip(small, tmp_path):
    path = tmp_path / "pano.zip"
    small.save(path)
    loaded = SafeGoalTD3.load(path, device="cpu")
    p = loaded.policy
    assert p.share_encoder and p.critic.features_extractor is p.encoder
    assert p.actor_target.features_extractor is p.encoder_target
    env = gym.make(ENV)
    states = env.unwrapped.sample_states(6, np.random.default_rng(0))
    obs = observations_at(env, states)
    np.testing.assert_allclose(loaded.distance(obs, obs[::-1]), small.distance(obs, obs[::-1]), rtol=1e-6)
    a1, _ = small.predict({"observation": obs, "achieved_goal": obs, "desired_goal": obs[::-1]}, deterministic=True)
    a2, _ = loaded.predict({"observation": obs, "achieved_goal": obs, "desired_goal": obs[::-1]}, deterministic=True)
    np.testing.assert_allclose(a1, a2, rtol=1e-6)
    # pairwise encodes each node once and agrees with the elementwise values
    D = loaded.pairwise_distance(obs, obs)
    np.testing.assert_allclose(np.diag(D), loaded.distance(obs, obs), rtol=1e-4, atol=1e-4)


def test_random_shift_moves_whole_samples_within_the_pad():
    x = th.arange(2 * 3 * 8 * 8 * 1, dtype=th.float32).reshape(2, 3, 8, 8, 1)
    aug = RandomShift(2, th.Generator().manual_seed(0))
    y = aug(x)
    assert y.shape == x.shape
    assert th.equal(RandomShift(0)(x), x)
    for b in range(2):  # one offset per sample, the same for every view
        for dy in range(-2, 3):
            for dx in range(-2, 3):
                rows = (th.arange(8) + dy).clamp(0, 7)
                cols = (th.arange(8) + dx).clamp(0, 7)
                if th.equal(y[b], x[b][:, rows][:, :, cols]):
                    break
            else:
                continue
            break
        else:
            pytest.fail(f"sample {b} is not a shifted copy")


@pytest.mark.slow
def test_a_short_panorama_run_learns_distances():
    """About a thousand updates from images: predicted distances start to tell far goals from near ones.

    Measured on 300 pairs: the chance that a pair over 2.5 m apart is predicted further than one
    under 1.5 m (0.5 for a blind critic) goes from 0.48-0.60 to 0.73-0.75 for seeds 0-2, and
    Spearman(predicted, geodesic) from 0.05-0.16 to 0.29-0.34.
    """
    th.manual_seed(0)
    env = gym.make(ENV)
    rng = np.random.default_rng(3)
    s, g, geo = sample_problems(env, 300, rng, max_distance=4.0)
    obs_s, obs_g = observations_at(env, s), observations_at(env, g)
    near, far = geo < 1.5, geo > 2.5
    assert near.sum() >= 30 and far.sum() >= 30

    def far_above_near(d: np.ndarray) -> float:
        return float((d[far][:, None] > d[near][None, :]).mean())

    model = model_on(learning_starts=200, batch_size=32, learning_rate=1e-3)
    before = model.distance(obs_s, obs_g)
    model.learn(1200)
    after = model.distance(obs_s, obs_g)
    a0, a1 = far_above_near(before), far_above_near(after)
    assert a1 >= 0.68 and a1 >= a0 + 0.1, f"P(far > near) {a0:.3f} -> {a1:.3f}"
    assert spearmanr(after, geo).statistic > spearmanr(before, geo).statistic + 0.1


def test_pre_encoded_nodes_score_like_raw_ones_and_are_encoded_once(small):
    from agents.search.graph.build import NodePairwise

    env = gym.make(ENV)
    rng = np.random.default_rng(3)
    nodes = observations_at(env, env.unwrapped.sample_states(40, rng))
    ends = observations_at(env, env.unwrapped.sample_states(6, rng))
    raw = small.pairwise(nodes, ends)
    codes = small.encode_observations(nodes)
    assert len(codes) == 40
    for a, b in zip(small.pairwise(codes, ends), raw):
        assert np.allclose(a, b, atol=1e-5)
    for a, b in zip(small.pairwise(ends, codes), small.pairwise(ends, nodes)):
        assert np.allclose(a, b, atol=1e-5)

    encoder = small.policy.encoder.encoder
    batch_sizes = []
    hook = encoder.register_forward_hook(lambda m, inp, out: batch_sizes.append(inp[0].shape[0]))
    try:
        fn = NodePairwise(small, nodes)
        for _ in range(3):  # e.g. three replans against new ends
            for a, b in zip(fn(nodes, ends), raw):
                assert np.allclose(a, b, atol=1e-5)
            fn(ends, nodes)
    finally:
        hook.remove()
    assert sum(s == 40 for s in batch_sizes) == 1  # the nodes once, the ends at every call
    other = model_on()
    with pytest.raises(ValueError, match="encoded by another policy"):
        other.pairwise(codes, ends)
    with pytest.raises(ValueError, match="takes a batch"):
        small.encode_observations(nodes[0])
