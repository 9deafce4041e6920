"""SafeGoalTD3: training improves the critics, save/load round trips, clear checkpoint errors."""
import os
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from scipy.stats import spearmanr
from stable_baselines3.common.noise import NormalActionNoise

import safe_mapf_envs  # noqa: F401
from agents import CheckpointError, SafeGoalTD3
from agents.evaluation import sample_problems
from agents.self_sampling import OracleSampler, ProblemResetWrapper, SelfSampler

th.set_num_threads(1)  # the machine is small and shared; one thread is also the fastest here

SMALL = dict(net_arch=[32, 32], features_extractor_kwargs={"net_arch": [32]})


def small_model(env_id="SafeCenterDot-v0", **kw):
    args = dict(learning_starts=100, batch_size=32, seed=0, device="cpu", policy_kwargs=SMALL,
                action_noise=NormalActionNoise(np.zeros(2), 0.2 * np.ones(2)))
    args.update(kw)
    return SafeGoalTD3("MultiInputPolicy", env_id, **args)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A short run on the small CenterDot map (a few hundred gradient steps)."""
    th.manual_seed(0)
    model = SafeGoalTD3(
        "MultiInputPolicy", "SafeCenterDot-v0", learning_starts=300, batch_size=64, seed=0, device="cpu",
        learning_rate=1e-3, action_noise=NormalActionNoise(np.zeros(2), 0.3 * np.ones(2)),
        problem_sampler="self", problem_sampler_kwargs=dict(target_distance=(1, 10), n_candidates=200, n_keep=20),
        policy_kwargs=dict(net_arch=[64, 64], features_extractor_kwargs={"net_arch": [64]}),
    )
    env = gym.make("SafeCenterDot-v0")
    rng = np.random.default_rng(7)
    s, g, geo = sample_problems(env, 300, rng, max_distance=12.0)
    obs_s, obs_g = env.unwrapped.normalize(s), env.unwrapped.normalize(g)
    before = spearmanr(model.distance(obs_s, obs_g), geo).statistic
    model.learn(1500)
    after = spearmanr(model.distance(obs_s, obs_g), geo).statistic
    return model, before, after, (obs_s, obs_g, geo)


@pytest.mark.slow
def test_training_makes_predicted_distance_track_true_distance(trained):
    model, before, after, _ = trained
    assert model.num_timesteps == 1500
    assert after > 0.6, f"Spearman after training {after:.3f}"
    assert after > before + 0.3, f"Spearman {before:.3f} -> {after:.3f}"


@pytest.mark.slow
def test_cost_is_recorded_and_critic_predicts_more_cost_near_the_block(trained):
    model, *_ = trained
    buf = model.replay_buffer
    n = buf.pos
    assert np.all(buf.costs[:n] >= 0) and buf.costs[:n].max() > 0.5
    env = gym.make("SafeCenterDot-v0").unwrapped
    # the block is [6, 9]^2 with cost radius 3: a trip along its side costs, one along the wall does not
    near = model.cost(env.normalize([[5.0, 4.0]]), env.normalize([[10.0, 4.0]]), aggregate="mean")
    far = model.cost(env.normalize([[5.0, 13.8]]), env.normalize([[10.0, 13.8]]), aggregate="mean")
    assert near[0] > far[0] + 0.3


@pytest.mark.slow
def test_self_sampler_is_used_and_refills(trained):
    model, *_ = trained
    assert isinstance(model.sampler, SelfSampler)
    assert model.sampler.n_refills >= 2
    assert model.sampler.model is model


@pytest.mark.slow
def test_save_load_round_trip_keeps_critics_and_lambda(trained, tmp_path):
    model, *_ , (obs_s, obs_g, _) = trained
    model.lagrangian.value = 0.75
    model.constrained = True
    path = tmp_path / "m.zip"
    model.save(path)
    loaded = SafeGoalTD3.load(path, device="cpu")
    assert loaded.lagrange_multiplier == pytest.approx(0.75)
    assert loaded.constrained and loaded.env_id == "SafeCenterDot-v0"
    np.testing.assert_allclose(loaded.distance(obs_s, obs_g), model.distance(obs_s, obs_g), rtol=1e-6)
    np.testing.assert_allclose(loaded.cost(obs_s, obs_g), model.cost(obs_s, obs_g), rtol=1e-6)
    np.testing.assert_allclose(loaded.pairwise_cost(obs_s[:5], obs_g[:4]), model.pairwise_cost(obs_s[:5], obs_g[:4]),
                               rtol=1e-6)
    sd, sd2 = model.policy.cost_critic_target.state_dict(), loaded.policy.cost_critic_target.state_dict()
    assert all(th.equal(sd[k], sd2[k]) for k in sd)
    obs = {"observation": obs_s[:3], "achieved_goal": obs_s[:3], "desired_goal": obs_g[:3]}
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])
    # training continues from a loaded model, with the sampler and buffer rebuilt
    loaded.set_env(gym.make("SafeCenterDot-v0"))
    loaded.learning_starts = 0
    loaded.learn(50)
    assert loaded.num_timesteps == 50


@pytest.mark.slow
def test_lagrange_multiplier_rises_while_episodes_cost_too_much():
    model = small_model(constrained=True, cost_limit=0.0, lagrange_update_episodes=1, learning_starts=40)
    model.learn(200)
    assert model.lagrange_multiplier > 0
    assert len(model.ep_cost_buffer) > 0 and max(model.ep_cost_buffer) > 0
    unconstrained = small_model(learning_starts=40)
    unconstrained.learn(200)
    assert unconstrained.lagrange_multiplier == 0.0


def test_oracle_and_uniform_samplers():
    model = small_model(problem_sampler="oracle", problem_sampler_kwargs=dict(band=(1.0, 3.0)))
    assert isinstance(model.sampler, OracleSampler)
    model.learn(60)
    env = model.get_env().envs[0]
    wrapper = [w for w in [env, env.env] if isinstance(w, ProblemResetWrapper)]
    assert wrapper and wrapper[0].sampler is model.sampler
    obs, _ = wrapper[0].reset()
    u = wrapper[0].unwrapped
    d = u.geodesic_distance(u.position, u.goal)
    assert 1.0 - 0.3 <= float(d) <= 3.0 + 0.3
    assert small_model(problem_sampler="uniform").sampler.reset_options(None) is None


def _corrupt(src, dst, drop=None, truncate=None):
    data = open(src, "rb").read()
    if truncate is not None:
        open(dst, "wb").write(data[:truncate])
        return
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename != drop:
                zout.writestr(item, zin.read(item.filename))


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    path = tmp_path_factory.mktemp("ckpt") / "model.zip"
    small_model().save(path)
    return path


def test_truncated_zip_raises_clear_error(checkpoint, tmp_path):
    bad = tmp_path / "truncated.zip"
    _corrupt(checkpoint, bad, truncate=os.path.getsize(checkpoint) // 2)
    with pytest.raises(CheckpointError, match="truncated or corrupt"):
        SafeGoalTD3.load(bad)


def test_not_a_zip_raises_clear_error(tmp_path):
    bad = tmp_path / "junk.zip"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(CheckpointError, match="truncated or corrupt"):
        SafeGoalTD3.load(bad)


@pytest.mark.parametrize("drop, match", [("policy.pth", "policy.pth"), ("data", "no 'data'"),
                                         ("cost_critic.optimizer.pth", "cost_critic.optimizer")])
def test_missing_entries_raise_clear_error(checkpoint, tmp_path, drop, match):
    bad = tmp_path / "missing.zip"
    _corrupt(checkpoint, bad, drop=drop)
    with pytest.raises(CheckpointError, match=match):
        SafeGoalTD3.load(bad)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        SafeGoalTD3.load(tmp_path / "nothing.zip")


def test_checkpoint_for_another_env_raises_clear_error(checkpoint):
    other = gym.make("SafeCenterDot-v0")
    img = spaces.Box(0, 255, (4, 32, 32, 4), np.uint8)
    other.observation_space = spaces.Dict({"observation": img, "achieved_goal": img, "desired_goal": img})
    with pytest.raises(CheckpointError, match="does not fit"):
        SafeGoalTD3.load(checkpoint, env=other)


def test_mismatched_architecture_raises_clear_error(checkpoint, tmp_path):
    # networks of another size under the same names
    other = small_model(policy_kwargs=dict(net_arch=[16, 16], features_extractor_kwargs={"net_arch": [32]}))
    other_path = tmp_path / "other.zip"
    other.save(other_path)
    bad = tmp_path / "mixed.zip"
    with zipfile.ZipFile(checkpoint) as a, zipfile.ZipFile(other_path) as b, zipfile.ZipFile(bad, "w") as out:
        for item in a.infolist():
            src = b if item.filename == "policy.pth" else a
            out.writestr(item, src.read(item.filename))
    with pytest.raises(CheckpointError, match="do not match"):
        SafeGoalTD3.load(bad)


def test_loading_another_algorithms_checkpoint_is_refused(tmp_path):
    from stable_baselines3 import TD3

    path = tmp_path / "td3.zip"
    TD3("MultiInputPolicy", gym.make("SafeCenterDot-v0"), learning_starts=10, device="cpu").save(path)
    with pytest.raises(CheckpointError, match="not a SafeGoalPolicy"):
        SafeGoalTD3.load(path)


def test_progress_bar_works_without_rich(capsys):
    model = small_model()
    model.learn(20, progress_bar=True)
    assert model.num_timesteps == 20


def test_rejects_non_goal_env():
    with pytest.raises(ValueError, match="Dict"):
        SafeGoalTD3("MultiInputPolicy", gym.make("Pendulum-v1"), device="cpu")


def test_load_overrides_replace_settings_before_setup(checkpoint):
    env = gym.make("SafeCenterDot-v0")
    noise = NormalActionNoise(np.zeros(2), 0.5 * np.ones(2))
    model = SafeGoalTD3.load(checkpoint, env=env, device="cpu", learning_rate=1e-2, actor_learning_rate=2e-3,
                             batch_size=7, learning_starts=3, action_noise=noise, constrained=True,
                             problem_sampler="oracle", problem_sampler_kwargs=dict(band=(1.0, 2.0)),
                             cost_limit=4.0, lagrange_lr=0.5)
    assert model.batch_size == 7 and model.learning_starts == 3 and model.action_noise is noise
    assert model.lr_schedule(1.0) == pytest.approx(1e-2) and model.cost_lr_schedule(1.0) == pytest.approx(1e-2)
    assert model.actor_lr_schedule(1.0) == pytest.approx(2e-3)
    assert isinstance(model.sampler, OracleSampler) and model.sampler.band == (1.0, 2.0)
    assert model.constrained
    lag = model.lagrangian
    assert (lag.cost_limit, lag.learning_rate, lag.value) == (4.0, 0.5, 0.0)  # init from the stored value
    # the networks are the checkpoint's
    plain = SafeGoalTD3.load(checkpoint, device="cpu")
    sd, sd2 = plain.policy.state_dict(), model.policy.state_dict()
    assert all(th.equal(sd[k], sd2[k]) for k in sd)


def test_load_with_a_seed_is_reproducible(checkpoint):
    def run():
        m = SafeGoalTD3.load(checkpoint, env=gym.make("SafeCenterDot-v0"), device="cpu", seed=5, learning_starts=10)
        m.learn(40)
        return m.replay_buffer.observations["observation"][:40].copy(), m.policy.state_dict()

    (o1, s1), (o2, s2) = run(), run()
    np.testing.assert_array_equal(o1, o2)
    assert all(th.equal(s1[k], s2[k]) for k in s1)


def test_load_refuses_unknown_overrides(checkpoint):
    with pytest.raises(TypeError, match="unknown overrides.*learnin_rate"):
        SafeGoalTD3.load(checkpoint, device="cpu", learnin_rate=1e-3)


def test_problem_sampling_callback_installs_its_sampler():
    from agents.self_sampling import ProblemSamplingCallback

    model = small_model(problem_sampler="uniform", learning_starts=10)
    callback = ProblemSamplingCallback("oracle", band=(1.0, 2.0))
    model.learn(30, callback=callback)
    env = model.get_env().envs[0]
    wrapper = [w for w in [env, env.env] if isinstance(w, ProblemResetWrapper)][0]
    assert wrapper.sampler is callback.sampler and isinstance(callback.sampler, OracleSampler)
    wrapper.reset()
    u = wrapper.unwrapped
    assert 1.0 - 0.3 <= float(u.geodesic_distance(u.position, u.goal)) <= 2.0 + 0.3


def test_sampler_needs_a_reset_wrapper():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.self_sampling import install_sampler

    bare = DummyVecEnv([lambda: gym.make("SafeCenterDot-v0")])
    with pytest.raises(ValueError, match="no ProblemResetWrapper"):
        install_sampler(bare, SelfSampler())


def test_importing_the_algorithm_neither_registers_envs_nor_closes_a_circle():
    import subprocess
    import sys

    code = ("import sys, gymnasium as gym; import agents.self_sampling; "
            "assert 'agents.algorithm' not in sys.modules, 'self_sampling imports the algorithm'; "
            "import agents.algorithm; "
            "assert 'safe_mapf_envs' not in sys.modules and 'SafeCenterDot-v0' not in gym.registry; "
            "import safe_mapf_envs; assert 'SafeCenterDot-v0' in gym.registry")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_a_string_env_id_registers_the_environments_itself():
    import subprocess
    import sys

    code = ("from agents.algorithm import SafeGoalTD3; "
            "m = SafeGoalTD3('MultiInputPolicy', 'SafeCenterDot-v0', device='cpu', learning_starts=1); "
            "assert m.env_id == 'SafeCenterDot-v0'")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_tensorboard_writes_an_event_file(tmp_path):
    pytest.importorskip("tensorboard", reason="tensorboard (a dependency of the package) is not installed")
    model = small_model(tensorboard_log=str(tmp_path), learning_starts=10)
    model.learn(60, log_interval=1, tb_log_name="tiny")
    events = list(tmp_path.rglob("events.out.tfevents.*"))
    assert events and events[0].stat().st_size > 0


def test_constructor_settings_reach_the_base_class():
    m = small_model(buffer_size=1234, learning_starts=7, batch_size=9, tau=0.3, train_freq=2, gradient_steps=3)
    got = (m.buffer_size, m.learning_starts, m.batch_size, m.tau, m.gamma, m.gradient_steps)
    assert got == (1234, 7, 9, 0.3, 1.0, 3)
    assert m.train_freq.frequency == 2 and m.replay_buffer.buffer_size == 1234
