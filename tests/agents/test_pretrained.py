"""The shipped checkpoints: present, small, loadable, sensible; clear errors otherwise."""
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th

import safe_mapf_envs  # noqa: F401
from agents import CheckpointError, SafeGoalTD3, load_pretrained
from agents.evaluation import run_episodes, sample_problems
from agents.pretrained import KINDS, available, pretrained_path

th.set_num_threads(1)
ENV = "SafeCentralObstacle-v0"


@pytest.fixture(scope="module", params=["unconstrained", "constrained"])
def model(request):
    return request.param, load_pretrained(ENV, request.param)


def test_both_kinds_are_shipped_and_small():
    assert {(ENV, "unconstrained"), (ENV, "constrained")} <= set(available())
    for kind in ("unconstrained", "constrained"):
        assert os.path.getsize(pretrained_path(ENV, kind)) < 5_000_000


def test_loaded_model_has_the_planner_api(model):
    kind, m = model
    assert isinstance(m, SafeGoalTD3) and m.env_id == ENV
    assert m.constrained == (kind == "constrained")
    assert m.lagrange_multiplier >= 0.0
    assert m.policy.n_critics >= 3 and m.policy.n_cost_critics >= 3
    u = gym.make(ENV).unwrapped
    a = u.normalize([[5.0, 5.0], [5.0, 5.0], [5.0, 5.0]])
    b = u.normalize([[7.0, 5.0], [13.0, 5.0], [19.0, 5.0]])
    d = m.distance(a, b)
    assert np.all(np.diff(d) > 2.0), d  # farther goals take more steps (6 units apart = 6 steps)
    assert m.pairwise_distance(a, b).shape == (3, 3)
    # a trip hugging the block costs more than one along the outer wall
    near = m.cost(u.normalize([[18.0, 22.0]]), u.normalize([[18.0, 33.0]]), aggregate="mean")
    far = m.cost(u.normalize([[2.0, 22.0]]), u.normalize([[2.0, 33.0]]), aggregate="mean")
    assert near[0] > far[0] + 5.0


def test_loaded_policy_reaches_nearby_goals(model):
    _, m = model
    env = gym.make(ENV)
    s, g, _ = sample_problems(env, 20, np.random.default_rng(99), max_distance=10.0)
    assert run_episodes(m, env, s, g)["success"].mean() >= 0.9


def test_unknown_kind_or_env():
    with pytest.raises(ValueError, match="kind"):
        load_pretrained(ENV, "reckless")
    with pytest.raises(ValueError, match="available"):
        load_pretrained("SafeMaze-v0", "unconstrained")


def test_checkpoint_of_another_env_is_refused():
    with pytest.raises(CheckpointError, match="trained on"):
        load_pretrained("SafeCenterDot-v0", path=pretrained_path(ENV, "unconstrained"))


APARTMENTS = sorted({e for e, _ in available() if e.startswith("SafeApartment")})


def test_every_apartment_ships_both_stages():
    assert set(available()) >= {(f"SafeApartment{k}-v0", kind) for k in range(4) for kind in KINDS}


@pytest.mark.slow
@pytest.mark.parametrize("env_id", APARTMENTS)
def test_shipped_apartment_agents_load_and_see_distances(env_id):
    """Every shipped apartment has both stages, each under 10 MB, loadable on a CPU; the
    unconstrained critic ranks goals by their true distance and the policy acts on panoramas."""
    from scipy.stats import spearmanr

    from agents.self_sampling import observations_at

    env = gym.make(env_id)
    s, g, geo = sample_problems(env, 60, np.random.default_rng(11), max_distance=4.0)
    obs_s, obs_g = observations_at(env, s), observations_at(env, g)
    for kind in ("unconstrained", "constrained"):
        assert os.path.getsize(pretrained_path(env_id, kind)) < 10_000_000
        m = load_pretrained(env_id, kind, device="cpu")
        assert m.env_id == env_id and m.policy.share_encoder
        assert m.constrained == (kind == "constrained")
        actions, _ = m.predict({"observation": obs_s, "achieved_goal": obs_s, "desired_goal": obs_g},
                               deterministic=True)
        assert actions.shape == (60, 2) and np.all(np.abs(actions) <= 1.0)
        rho = spearmanr(m.distance(obs_s, obs_g), geo).statistic
        assert rho > 0.6, f"{env_id} {kind}: Spearman {rho:.3f}"


def test_centerdot_agents_are_shipped_and_the_constrained_one_is_safer():
    """The setting of the paper's Table I: both stages load, reach nearby goals, and the
    fine-tuned agent pays less cost on the same problems."""
    env_id = "SafeCenterDot-v0"
    env = gym.make(env_id)
    s, g, _ = sample_problems(env, 40, np.random.default_rng(5), max_distance=10.0)
    out = {}
    for kind in KINDS:
        assert os.path.getsize(pretrained_path(env_id, kind)) < 5_000_000
        m = load_pretrained(env_id, kind)
        assert m.env_id == env_id and m.constrained == (kind == "constrained")
        out[kind] = run_episodes(m, env, s, g)
        assert out[kind]["success"].mean() >= 0.9
    assert out["constrained"]["cost"].mean() < out["unconstrained"]["cost"].mean()


def test_every_shipped_checkpoint_names_classes_that_still_exist():
    """SB3 stores the classes a checkpoint needs (policy, replay buffer, Lagrange multiplier) by
    module path; moving one of them would make its load drop or fail. Each stored object
    deserialises, and the policy class is the one SafeGoalTD3 builds (the MARL baselines' policies
    are checked in ``test_marl_pretrained.py``)."""
    import base64
    import json
    import zipfile

    import cloudpickle

    from agents.buffers import GoalCostReplayBuffer
    from agents.lagrangian import LagrangeMultiplier
    from agents.policies import SafeGoalPolicy

    folder = Path(pretrained_path(ENV, "unconstrained")).parent
    checkpoints = sorted([*folder.glob("*_unconstrained.zip"), *folder.glob("*_constrained.zip")])
    assert len(checkpoints) >= 12
    for path in checkpoints:
        data = json.loads(zipfile.ZipFile(path).read("data"))
        objects = {key: cloudpickle.loads(base64.b64decode(value[":serialized:"]))
                   for key, value in data.items() if isinstance(value, dict) and ":serialized:" in value}
        assert objects["policy_class"] is SafeGoalPolicy, path.name
        assert objects["replay_buffer_class"] is GoalCostReplayBuffer, path.name
        assert isinstance(objects["lagrangian"], LagrangeMultiplier), path.name
