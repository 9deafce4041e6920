"""The thread rule of critic queries (agents.threads) and its use by SafeGoalTD3's query methods."""
import numpy as np
import pytest
import torch as th

from agents import threads
from agents.threads import ENV_VAR, inference_threads, torch_default_threads, torch_threads


@pytest.fixture
def clean_env(monkeypatch):
    """No thread variables set, and torch at its start-up count."""
    for name in (ENV_VAR, "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    before = th.get_num_threads()
    th.set_num_threads(torch_default_threads())
    yield monkeypatch
    th.set_num_threads(before)


def test_default_is_one_thread(clean_env):
    assert inference_threads() == 1


def test_argument_wins_over_everything(clean_env):
    clean_env.setenv(ENV_VAR, "3")
    clean_env.setenv("OMP_NUM_THREADS", "2")
    assert inference_threads(4) == 4


def test_environment_variable(clean_env):
    clean_env.setenv(ENV_VAR, " 3 ")
    assert inference_threads() == 3
    clean_env.setenv(ENV_VAR, "many")
    with pytest.raises(ValueError, match=ENV_VAR):
        inference_threads()


def test_a_count_the_user_chose_is_kept(clean_env, monkeypatch):
    monkeypatch.setattr(threads, "torch_default_threads", lambda: 8)  # torch now runs 1 != 8: set by the user
    th.set_num_threads(1)
    assert inference_threads() is None
    monkeypatch.setattr(threads, "torch_default_threads", lambda: th.get_num_threads())
    assert inference_threads() == 1
    clean_env.setenv("OMP_NUM_THREADS", "2")
    assert inference_threads() is None


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "x"])
def test_invalid_counts_are_refused(clean_env, bad):
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        inference_threads(bad)


def test_torch_threads_restores_the_setting():
    before = th.get_num_threads()
    target = 2 if before == 1 else 1
    with torch_threads(target):
        assert th.get_num_threads() == target
    assert th.get_num_threads() == before
    with pytest.raises(RuntimeError):
        with torch_threads(target):
            raise RuntimeError("boom")
    assert th.get_num_threads() == before
    with torch_threads(None):
        assert th.get_num_threads() == before


def test_model_queries_run_with_the_chosen_count_and_restore(clean_env, monkeypatch):
    from agents import SafeGoalTD3

    model = SafeGoalTD3("MultiInputPolicy", "SafeCenterDot-v0", learning_starts=10, device="cpu", seed=0,
                        policy_kwargs=dict(net_arch=[16], features_extractor_kwargs={"net_arch": [16]}))
    seen = []
    real = model.policy.pairwise

    def spy(*args, **kwargs):
        seen.append(th.get_num_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(model.policy, "pairwise", spy)
    obs = np.random.default_rng(0).uniform(0.1, 0.9, size=(5, 2)).astype(np.float32)
    before = th.get_num_threads()
    d1, _ = model.pairwise(obs, obs)
    d2, _ = model.pairwise(obs, obs, threads=2)
    assert seen == [1, 2] and th.get_num_threads() == before
    np.testing.assert_allclose(d1, d2, rtol=1e-6)
    assert model.distance(obs, obs, threads=1).shape == (5,)
    with pytest.raises(ValueError, match="threads"):
        model.cost(obs, obs, threads=0)


def test_pairwise_progress_bar(capsys):
    from agents import SafeGoalTD3

    model = SafeGoalTD3("MultiInputPolicy", "SafeCenterDot-v0", learning_starts=10, device="cpu", seed=0,
                        policy_kwargs=dict(net_arch=[16], features_extractor_kwargs={"net_arch": [16]}))
    obs = np.random.default_rng(0).uniform(0.1, 0.9, size=(40, 2)).astype(np.float32)
    model.pairwise_distance(obs, obs, chunk_size=100, progress=True)
    assert "pairwise" in capsys.readouterr().err
    for progress in (None, False):  # a short build shows no bar by default
        model.pairwise_distance(obs, obs, chunk_size=100, progress=progress)
        assert capsys.readouterr().err == ""
