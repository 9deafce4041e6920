"""Loading never runs code from a file: crafted archives are refused (or load harmlessly) on every
load path, shipped checkpoints load as before, and corrupt, truncated or NaN files are refused by name."""
import base64
import io
import json
import pickle
import shutil
import zipfile

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.noise import NormalActionNoise

import safe_mapf_envs  # noqa: F401
from agents import CheckpointError, SafeGoalTD3, load_pretrained
from agents.checkpoints import check_checkpoint, read_checkpoint
from agents.marl import load_marl, load_marl_pretrained
from agents.pretrained import pretrained_path
from baselines.cli import main

th.set_num_threads(1)


class Payload:
    """Unpickling it creates the file ``marker``: what a hostile checkpoint would do, made harmless."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def payload_entry(marker, type_name="<class 'abc.ABCMeta'>", **plain):
    blob = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    return {":type:": type_name, ":serialized:": blob, **plain}


def rewrite(src, dst, data=None, members=None, drop=()):
    """Copy the archive ``src`` to ``dst``, its ``data`` JSON edited by ``data(d)`` and members
    replaced or added from ``members`` (name -> bytes)."""
    members = dict(members or {})
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            if name in drop or name in members:
                continue
            content = zin.read(name)
            if name == "data" and data is not None:
                d = json.loads(content)
                data(d)
                content = json.dumps(d).encode()
            zout.writestr(name, content)
        for name, content in members.items():
            zout.writestr(name, content)
    return dst


def with_entry(key, entry):
    def edit(d):
        d[key] = entry
    return edit


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    path = tmp_path_factory.mktemp("ckpt") / "model.zip"
    SafeGoalTD3("MultiInputPolicy", "SafeCenterDot-v0", learning_starts=10, seed=0, device="cpu",
                policy_kwargs=dict(net_arch=[8], features_extractor_kwargs={"net_arch": [8]}),
                action_noise=NormalActionNoise(np.zeros(2), 0.2 * np.ones(2))).save(path)
    return path


@pytest.fixture
def crafted(checkpoint, tmp_path):
    """A checkpoint whose ``policy_class`` is a payload that creates ``marker``."""
    marker = tmp_path / "marker"
    path = rewrite(checkpoint, tmp_path / "crafted.zip",
                   data=with_entry("policy_class", payload_entry(marker, __module__="agents.policies")))
    return path, marker


def test_the_payload_is_live_under_a_plain_sb3_load(crafted):
    """The crafted file is a real attack: Stable-Baselines3's own reader runs it."""
    from stable_baselines3.common.save_util import load_from_zip_file

    path, marker = crafted
    load_from_zip_file(path, device="cpu")
    assert marker.exists()


@pytest.mark.parametrize("load", [
    lambda p: SafeGoalTD3.load(p, device="cpu"),
    lambda p: SafeGoalTD3.load(io.BytesIO(p.read_bytes()), device="cpu"),
    lambda p: SafeGoalTD3.load(p, device="cpu", learning_rate=1e-3),
    lambda p: check_checkpoint(p),
    lambda p: read_checkpoint(p),
    lambda p: load_pretrained("SafeCenterDot-v0", path=str(p)),
], ids=["load", "load-stream", "load-overrides", "check_checkpoint", "read_checkpoint", "load_pretrained"])
def test_a_crafted_policy_class_is_refused_on_every_python_path(crafted, load):
    path, marker = crafted
    with pytest.raises(CheckpointError, match=r"crafted.zip|<stream>") as err:
        load(path)
    assert "'policy_class'" in str(err.value) and "not a plain reference to a class" in str(err.value)
    assert not marker.exists()


@pytest.mark.parametrize("key, entry_type, plain, refused", [
    ("replay_buffer_class", "<class 'abc.ABCMeta'>", {}, "not a plain reference to a class"),
    ("train_freq", "<class 'stable_baselines3.common.type_aliases.TrainFreq'>", {}, "not a plain TrainFreq"),
    ("lagrangian", "<class 'builtins.object'>", {}, "expected a LagrangeMultiplier"),
    ("learning_rate", "<class 'function'>", {}, "schedule"),
    ("evil", "<class 'builtins.object'>", {}, "do not hold"),
    ("policy_kwargs", "<class 'dict'>", {"net_arch": [8]}, "do not hold"),
    # entries whose plain fields describe them: rebuilt from those, the payload never read
    ("action_noise", "<class 'stable_baselines3.common.noise.NormalActionNoise'>",
     {"_mu": "[0. 0.]", "_sigma": "[0.2 0.2]", "_dtype": "<class 'numpy.float32'>"}, None),
    ("observation_space", "<class 'gymnasium.spaces.dict.Dict'>",
     {"spaces": "{'achieved_goal': Box(0.0, 1.0, (2,), float32), 'desired_goal': Box(0.0, 1.0, (2,), float32), "
                "'observation': Box(0.0, 1.0, (2,), float32)}"}, None),
    ("ep_info_buffer", "<class 'collections.deque'>", {}, None),
    ("_last_obs", "<class 'collections.OrderedDict'>", {}, None),
])
def test_every_serialized_entry_is_rebuilt_or_refused_never_unpickled(checkpoint, tmp_path, key, entry_type,
                                                                      plain, refused):
    marker = tmp_path / "marker"
    path = rewrite(checkpoint, tmp_path / "crafted.zip", data=with_entry(key, payload_entry(marker, entry_type,
                                                                                             **plain)))
    if refused:
        with pytest.raises(CheckpointError, match=rf"crafted.zip: entry '{key}' .*{refused}"):
            SafeGoalTD3.load(path, device="cpu")
    else:
        model = SafeGoalTD3.load(path, device="cpu")
        assert model.env_id == "SafeCenterDot-v0"
        obs = {k: np.full((1, 2), 0.5, np.float32) for k in ("observation", "achieved_goal", "desired_goal")}
        assert model.predict(obs, deterministic=True)[0].shape == (1, 2)
    assert not marker.exists()


def test_an_overridden_entry_is_not_read(checkpoint, tmp_path):
    marker = tmp_path / "marker"
    path = rewrite(checkpoint, tmp_path / "crafted.zip",
                   data=with_entry("action_noise", payload_entry(marker, "<class 'builtins.object'>")))
    noise = NormalActionNoise(np.zeros(2), 0.1 * np.ones(2))
    assert SafeGoalTD3.load(path, device="cpu", action_noise=noise).action_noise is noise
    with pytest.raises(CheckpointError, match="'action_noise'"):
        SafeGoalTD3.load(path, device="cpu")
    assert not marker.exists()


def test_a_pickle_in_a_tensor_file_is_refused(checkpoint, tmp_path):
    marker = tmp_path / "marker"
    buf = io.BytesIO()
    th.save({"w": th.zeros(2), "evil": Payload(marker)}, buf)
    path = rewrite(checkpoint, tmp_path / "crafted.zip", members={"policy.pth": buf.getvalue()})
    with pytest.raises(CheckpointError, match="crafted.zip: policy.pth is not a readable weights-only"):
        SafeGoalTD3.load(path, device="cpu")
    assert not marker.exists()


@pytest.mark.parametrize("edit, match", [
    (dict(members={"evil.pkl": b"x"}), r"holds entries .* does not: \['evil.pkl'\]"),
    (dict(data=with_entry("policy_class", "agents.policies.SafeGoalPolicy")), "'policy_class' .* not a serialized"),
    (dict(data=with_entry("observation_space", [0, 1])), "'observation_space' .* not a serialized"),
    (dict(members={"data": b"[1, 2]"}, drop=("data",)), "not a JSON object"),
    (dict(members={"data": b"{not json"}, drop=("data",)), "not JSON"),
])
def test_unexpected_archives_are_refused_by_name(checkpoint, tmp_path, edit, match):
    path = rewrite(checkpoint, tmp_path / "odd.zip", **edit)
    with pytest.raises(CheckpointError, match=f"odd.zip.*{match}"):
        SafeGoalTD3.load(path, device="cpu")


def test_non_finite_weights_are_refused_naming_the_tensor(checkpoint, tmp_path):
    with zipfile.ZipFile(checkpoint) as z:
        sd = th.load(io.BytesIO(z.read("policy.pth")), weights_only=True)
    name = next(k for k, v in sd.items() if v.is_floating_point() and v.numel() > 1)
    sd[name] = th.full_like(sd[name], float("nan"))
    buf = io.BytesIO()
    th.save(sd, buf)
    path = rewrite(checkpoint, tmp_path / "nan.zip", members={"policy.pth": buf.getvalue()})
    with pytest.raises(CheckpointError, match=rf"nan.zip: policy.pth holds non-finite values .*{name}"):
        SafeGoalTD3.load(path, device="cpu")


def test_a_bit_flip_or_truncation_is_refused_naming_the_file(checkpoint, tmp_path, flip_byte):
    flipped = flip_byte(checkpoint, tmp_path / "flipped.zip", "policy.pth")
    with pytest.raises(CheckpointError, match="flipped.zip is not a readable checkpoint .*truncated or corrupt"):
        SafeGoalTD3.load(flipped, device="cpu")
    cut = tmp_path / "cut.zip"
    cut.write_bytes(checkpoint.read_bytes()[:-200])
    with pytest.raises(CheckpointError, match="cut.zip is not a readable checkpoint .*truncated or corrupt"):
        SafeGoalTD3.load(cut, device="cpu")


# ---------------------------------------------------------------------- the command line
TINY = ["--env", "SafeCenterDot-v0", "--learning-starts", "50", "--eval-problems", "2", "--eval-pairs", "5",
        "--eval-max-distance", "5", "--no-progress", "--net-arch", "8", "--encoder-arch", "8",
        "--n-candidates", "20", "--n-keep", "5"]


def test_evaluate_refuses_a_crafted_checkpoint(crafted, tmp_path, capsys):
    path, marker = crafted
    rc = main(["evaluate", "--env", "SafeCenterDot-v0", "--unconstrained", str(path), "--out", str(tmp_path / "ev")])
    assert rc == 2 and "'policy_class'" in capsys.readouterr().err
    assert not marker.exists()


def test_train_init_refuses_a_crafted_checkpoint(crafted, tmp_path, capsys):
    path, marker = crafted
    rc = main(["train", "--stage", "constrained", "--init", str(path), "--out", str(tmp_path / "c"),
               "--timesteps", "60", "--eval-freq", "60", *TINY])
    assert rc == 2 and "'policy_class'" in capsys.readouterr().err
    assert not marker.exists()


@pytest.mark.slow
def test_train_resume_refuses_a_crafted_resume_point(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), "--timesteps", "60", "--eval-freq", "60", "--replay-save-freq", "60",
                 *TINY]) == 0
    state = json.loads((out / "resume" / "state.json").read_text())
    saved = out / "resume" / state.get("model", "model.zip")
    marker = tmp_path / "marker"
    crafted = rewrite(saved, tmp_path / "crafted.zip",
                      data=with_entry("policy_class", payload_entry(marker, __module__="agents.policies")))
    shutil.copy(crafted, saved)
    capsys.readouterr()
    rc = main(["train", "--out", str(out), "--resume", "--timesteps", "120", "--eval-freq", "60",
               "--replay-save-freq", "60", *TINY])
    assert rc == 2 and "'policy_class'" in capsys.readouterr().err
    assert not marker.exists()


# ---------------------------------------------------------------------- multi-agent policies
@pytest.fixture
def ippo_copy(tmp_path):
    src = pretrained_path("SafeCenterDot-v0").replace("_unconstrained.zip", "_ippo.zip")
    dst = tmp_path / "model.zip"
    shutil.copy(src, dst)
    shutil.copy(src.replace(".zip", ".json"), tmp_path / "model.json")
    return dst


@pytest.mark.parametrize("key", ["policy_class", "rollout_buffer_class", "clip_range", "evil"])
def test_a_crafted_ippo_file_is_refused(ippo_copy, tmp_path, key):
    marker = tmp_path / "marker"
    crafted = rewrite(ippo_copy, tmp_path / "crafted.zip", data=with_entry(key, payload_entry(marker)))
    shutil.move(crafted, ippo_copy)
    with pytest.raises(CheckpointError, match=rf"model.zip: entry '{key}'"):
        load_marl(str(ippo_copy))
    with pytest.raises(CheckpointError, match=rf"model.zip: entry '{key}'"):
        load_marl_pretrained("SafeCenterDot-v0", "ippo", path=str(ippo_copy))
    assert not marker.exists()


def test_a_crafted_mappo_file_is_refused(tmp_path):
    marker = tmp_path / "marker"
    src = pretrained_path("SafeCenterDot-v0").replace("_unconstrained.zip", "_mappo_lag.pt")
    ckpt = th.load(src, weights_only=True)
    ckpt["evil"] = Payload(marker)
    th.save(ckpt, tmp_path / "model.pt")
    shutil.copy(src.replace(".pt", ".json"), tmp_path / "model.json")
    with pytest.raises(ValueError, match="model.pt: the checkpoint is not a readable weights-only"):
        load_marl(str(tmp_path / "model.pt"))
    assert not marker.exists()


@pytest.mark.parametrize("algo, suffix", [("ippo", ".zip"), ("mappo_lag", ".pt")])
def test_truncated_flipped_or_nan_marl_files_are_refused_naming_the_file(tmp_path, algo, suffix, flip_byte):
    src = pretrained_path("SafeCenterDot-v0").replace("_unconstrained.zip", f"_{algo}{suffix}")
    shutil.copy(src.replace(suffix, ".json"), tmp_path / "model.json")
    path = tmp_path / f"model{suffix}"
    raw = open(src, "rb").read()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match=rf"model{suffix} is not a readable .*truncated or corrupt"):
        load_marl(str(path))
    member = "policy.pth" if suffix == ".zip" else next(n for n in zipfile.ZipFile(src).namelist()
                                                        if n.endswith("data.pkl"))
    flip_byte(type(path)(src), path, member)
    with pytest.raises(ValueError, match=rf"model{suffix} is not a readable .*truncated or corrupt"):
        load_marl(str(path))
    if suffix == ".pt":
        ckpt = th.load(src, weights_only=True)
        name = next(iter(ckpt["nets"]))
        ckpt["nets"][name] = th.full_like(ckpt["nets"][name], float("inf"))
        th.save(ckpt, path)
        with pytest.raises(ValueError, match=rf"model.pt: .*non-finite .*nets.{name}"):
            load_marl(str(path))
    (tmp_path / "model.json").write_text("{trunc")
    with pytest.raises(ValueError, match="model.json. is not valid JSON"):
        load_marl(str(path))


# ---------------------------------------------------------------------- shipped checkpoints
@pytest.mark.parametrize("env_id, kind", [("SafeCenterDot-v0", "constrained"), ("SafeApartment0-v0", "unconstrained")])
def test_shipped_checkpoints_load_as_a_full_unpickling_load_did(env_id, kind):
    """The shipped files are trusted: a plain Stable-Baselines3 load (which unpickles) is the
    reference that the safe load must match, weights, settings and actions."""
    from stable_baselines3.common.base_class import BaseAlgorithm

    path = pretrained_path(env_id, kind)
    safe = load_pretrained(env_id, kind)
    plain = BaseAlgorithm.load.__func__(SafeGoalTD3, path, device="cpu")
    a, b = safe.policy.state_dict(), plain.policy.state_dict()
    assert a.keys() == b.keys() and all(th.equal(a[k], b[k]) for k in a)
    assert safe.observation_space == plain.observation_space and safe.action_space == plain.action_space
    assert safe.train_freq == plain.train_freq and safe.replay_buffer_class is plain.replay_buffer_class
    assert vars(safe.lagrangian) == vars(plain.lagrangian)
    assert safe.lr_schedule(0.5) == plain.lr_schedule(0.5)
    np.testing.assert_array_equal(safe.action_noise._sigma, plain.action_noise._sigma)
    rng = np.random.default_rng(0)
    safe.observation_space.seed(0)
    obs = {k: np.stack([s.sample() for _ in range(4)]) for k, s in safe.observation_space.spaces.items()}
    np.testing.assert_array_equal(safe.predict(obs, deterministic=True)[0], plain.predict(obs, deterministic=True)[0])
    if env_id == "SafeCenterDot-v0":
        o, g = rng.random((6, 2)).astype(np.float32), rng.random((6, 2)).astype(np.float32)
        np.testing.assert_array_equal(safe.distance(o, g), plain.distance(o, g))
        np.testing.assert_array_equal(safe.cost(o, g), plain.cost(o, g))


@pytest.mark.parametrize("env_id", ["SafeCenterDot-v0", "SafeCentralObstacle-v0"])
def test_shipped_marl_policies_act_as_a_full_unpickling_load_did(env_id):
    from stable_baselines3 import PPO

    agent = load_marl_pretrained(env_id, "ippo")
    plain = PPO.load(pretrained_path(env_id).replace("_unconstrained.zip", "_ippo.zip"), device="cpu")
    obs = np.random.default_rng(1).random((5, agent.obs_dim)).astype(np.float32)
    np.testing.assert_array_equal(agent.act(obs), plain.predict(obs, deterministic=True)[0])
    assert load_marl_pretrained(env_id, "mappo-lag").act(obs).shape == (5, 2)
