"""``safe-mapf train``: both stages end to end on a tiny map, files and errors."""
import json

import pytest
import torch as th

from agents import SafeGoalTD3
from baselines.cli import main

th.set_num_threads(1)

TINY = ["--env", "SafeCenterDot-v0", "--timesteps", "300", "--learning-starts", "100", "--eval-freq", "150",
        "--eval-problems", "5", "--eval-pairs", "20", "--eval-max-distance", "5", "--no-progress",
        "--net-arch", "16", "16", "--encoder-arch", "16", "--n-candidates", "50", "--n-keep", "10"]


@pytest.mark.slow
def test_train_both_stages(tmp_path, capsys):
    u, c = tmp_path / "u", tmp_path / "c"
    assert main(["train", "--stage", "unconstrained", "--out", str(u), *TINY]) == 0
    out = capsys.readouterr().out
    assert "SafeCenterDot-v0 unconstrained: 300 steps" in out and "[eval] steps=300" in out
    for name in ("model.zip", "checkpoint.zip", "config.json", "evaluations.jsonl", "summary.json"):
        assert (u / name).exists(), name
    config = json.loads((u / "config.json").read_text())
    assert config["config"]["stage"] == "unconstrained" and config["config"]["net_arch"] == [16, 16]
    assert "torch" in config["versions"]
    evals = [json.loads(line) for line in (u / "evaluations.jsonl").read_text().splitlines()]
    assert [e["timesteps"] for e in evals] == [150, 300]
    summary = json.loads((u / "summary.json").read_text())
    assert summary["timesteps"] == 300 and summary["wall_s"] > 0 and summary["cpu_s"] > 0

    assert main(["train", "--stage", "constrained", "--init", str(u / "model.zip"), "--out", str(c),
                 "--cost-limit", "0", "--lagrange-update-episodes", "1", "--target-cost", "5", "10", *TINY]) == 0
    model = SafeGoalTD3.load(c / "model.zip")
    assert model.constrained and model.lagrangian.cost_limit == 0.0
    assert model.lagrange_multiplier > 0  # every episode costs more than a zero limit
    assert model.sampler.target_cost == (5.0, 10.0)


def test_constrained_stage_needs_init(tmp_path, capsys):
    assert main(["train", "--stage", "constrained", "--out", str(tmp_path), *TINY]) == 2
    assert "--init" in capsys.readouterr().err


def test_missing_init_checkpoint(tmp_path, capsys):
    assert main(["train", "--stage", "constrained", "--init", str(tmp_path / "nope.zip"), *TINY]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.slow
def test_resume_continues_a_run_from_its_last_resume_point(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), "--replay-save-freq", "150", *TINY]) == 0
    full = json.loads((out / "summary.json").read_text())
    state = json.loads((out / "resume" / "state.json").read_text())
    assert state["timesteps"] == 300 and state["replay"] == "replay-300.npz"
    assert sorted(p.name for p in (out / "resume").iterdir()) == ["model-300.zip", "replay-300.npz", "state.json"]
    saved = SafeGoalTD3.load(out / "resume" / state["model"])
    assert saved.num_timesteps == 300 and saved._n_updates == state["gradient_steps"] == full["gradient_steps"]
    # continue the same run to 450 steps in all: counters, buffer and evaluation log carry over
    args = [a if a != "300" else "450" for a in TINY]
    assert main(["train", "--out", str(out), "--resume", *args]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["timesteps"] == 450 and summary["wall_s"] > full["wall_s"]
    evals = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert [e["timesteps"] for e in evals] == [150, 300, 450]
    assert evals[0]["wall_s"] <= evals[1]["wall_s"] <= evals[2]["wall_s"]  # wall time goes on, never back
    model = SafeGoalTD3.load(out / "model.zip")
    assert model.num_timesteps == 450
    # every gradient step an uninterrupted 450-step run takes: one per step after learning_starts
    assert summary["gradient_steps"] == model._n_updates == 450 - 100
    config = json.loads((out / "config.json").read_text())
    assert config["config"]["timesteps"] == 300 and config["resumed"][0]["config"]["timesteps"] == 450


def test_a_folder_that_holds_a_run_is_refused_without_resume_or_overwrite(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "model.zip").write_bytes(b"an earlier model")
    assert main(["train", "--out", str(out), *TINY]) == 2
    err = capsys.readouterr().err
    assert "not empty (model.zip)" in err and "--resume" in err and "--overwrite" in err
    assert (out / "model.zip").read_bytes() == b"an earlier model" and sorted(p.name for p in out.iterdir()) == [
        "model.zip"]


@pytest.mark.slow
def test_resume_refuses_another_map_and_overwrite_starts_anew(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), *TINY]) == 0
    (out / "notes.txt").write_text("mine")
    other = [a if a != "SafeCenterDot-v0" else "SafeCentralObstacle-v0" for a in TINY]
    assert main(["train", "--out", str(out), "--resume", *other]) == 2
    assert "--env: \"SafeCenterDot-v0\" there, \"SafeCentralObstacle-v0\" now" in capsys.readouterr().err
    assert main(["train", "--out", str(out), "--resume", "--seed", "9", *TINY]) == 2
    assert "--seed: 0 there, 9 now" in capsys.readouterr().err
    assert main(["train", "--out", str(out), "--overwrite", *other]) == 0
    assert json.loads((out / "summary.json").read_text())["env_id"] == "SafeCentralObstacle-v0"
    evals = [json.loads(line)["timesteps"] for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert evals == [150, 300]  # the earlier run's evaluations are gone
    assert (out / "notes.txt").read_text() == "mine"


def test_a_junk_init_checkpoint_is_refused_before_anything_is_written(tmp_path, capsys):
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip")
    out = tmp_path / "c"
    assert main(["train", "--stage", "constrained", "--init", str(junk), "--out", str(out), *TINY]) == 2
    assert "junk.zip" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_resume_without_a_resume_point_says_so(tmp_path, capsys):
    assert main(["train", "--out", str(tmp_path / "empty"), "--resume", *TINY]) == 2
    assert "nothing to resume" in capsys.readouterr().err


def test_help_states_each_default_once(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # undo the line wrapping
    assert "(default: True)" not in text and "(default: False)" not in text and "(default: None)" not in text
    assert "--no-progress hide the progress bar (it is drawn only when stderr is a terminal) --tensorboard" in text
    assert "evaluations.jsonl, summary.json --init" in text  # --out: its own default only
    assert "--timesteps TIMESTEPS environment steps of this stage (default: 30000)" in text


@pytest.mark.slow
def test_seeds_serially_and_on_ray_give_the_same_runs(tmp_path, capsys):
    serial = tmp_path / "serial"
    assert main(["train", "--seeds", "3", "4", "--out", str(serial), *TINY]) == 0
    out = capsys.readouterr().out
    assert "seed 3: 300 steps" in out and "seed 4: 300 steps" in out and "2 seeds in" in out
    combined = json.loads((serial / "summary.json").read_text())
    assert [r["seed"] for r in combined["runs"]] == [3, 4]
    for r in combined["runs"]:
        assert json.loads((serial / f"s{r['seed']}" / "summary.json").read_text())["seed"] == r["seed"]
    assert combined["success"]["min"] <= combined["success"]["mean"] <= combined["success"]["max"]

    ray = pytest.importorskip("ray")
    try:
        assert main(["train", "--seeds", "3", "4", "--ray", "--out", str(tmp_path / "ray"), *TINY]) == 0
    finally:
        ray.shutdown()
    on_ray = json.loads((tmp_path / "ray" / "summary.json").read_text())
    assert [{k: v for k, v in r.items() if k != "out_dir"} for r in on_ray["runs"]] == \
        [{k: v for k, v in r.items() if k != "out_dir"} for r in combined["runs"]]


def test_ray_without_seeds_is_refused(tmp_path, capsys):
    assert main(["train", "--ray", "--out", str(tmp_path), *TINY]) == 2
    assert "--seeds" in capsys.readouterr().err


def test_conv_layers_shape_a_new_image_encoder_and_survive_save_load(tmp_path):
    import argparse

    from agents.training import FULL_VIEW_CONV_LAYERS, build_model
    from baselines.commands import train as train_cmd

    parser = argparse.ArgumentParser()
    train_cmd.register(parser.add_subparsers())
    args = parser.parse_args(["train", "--env", "SafeApartment0-v0", "--conv-layers", "16,8,4", "32,3,2",
                              "--buffer-size", "500"])
    cfg = train_cmd.config_from_args(args)
    assert [tuple(c) for c in cfg.conv_layers] == list(FULL_VIEW_CONV_LAYERS)
    cfg.validate()
    model = build_model(cfg)
    enc = model.policy.encoder.encoder
    assert enc.read_size == (32, 32)  # every pixel of each view (the paper's layers: 20 x 20)
    model.save(tmp_path / "m.zip")
    loaded = SafeGoalTD3.load(tmp_path / "m.zip")
    assert loaded.policy.encoder.encoder.read_size == (32, 32)
    x = th.randint(0, 256, (2, 4, 32, 32, 4), dtype=th.uint8)
    assert th.equal(enc(x), loaded.policy.encoder.encoder(x))


@pytest.mark.parametrize("value", ["16,8", "16,8,x", "16,0,4"])
def test_bad_conv_layers_are_refused_by_name(value, capsys):
    with pytest.raises(SystemExit):
        main(["train", "--conv-layers", value, *TINY])
    assert "filters,kernel,stride" in capsys.readouterr().err


def test_conv_layers_do_not_apply_to_a_fine_tuned_checkpoint(tmp_path):
    from agents.training import TrainConfig

    ckpt = tmp_path / "m.zip"
    ckpt.write_bytes(b"")
    with pytest.raises(ValueError, match="keeps the checkpoint's encoder"):
        TrainConfig(stage="constrained", init=str(ckpt), conv_layers=[(16, 8, 4)]).validate()
    with pytest.raises(ValueError, match="triples of positive integers"):
        TrainConfig(conv_layers=[(16, 8)]).validate()


def test_augmentation_can_be_switched_on_when_continuing_a_checkpoint():
    from agents.pretrained import pretrained_path
    from agents.training import TrainConfig, build_model

    ckpt = pretrained_path("SafeApartment0-v0")
    on = build_model(TrainConfig(env_id="SafeApartment0-v0", init=ckpt, augmentation="shift", buffer_size=200))
    assert on.augmentation == "shift" and on.augment is not None
    kept = build_model(TrainConfig(env_id="SafeApartment0-v0", init=ckpt, buffer_size=200))
    assert kept.augmentation is None  # None keeps the checkpoint's setting


def test_parked_agents_reach_the_training_env(tmp_path):
    import argparse

    from agents.training import TrainConfig, build_model
    from baselines.commands import train as train_cmd

    parser = argparse.ArgumentParser()
    train_cmd.register(parser.add_subparsers())
    cfg = train_cmd.config_from_args(parser.parse_args(["train", "--env", "SafeApartment0-v0", "--parked-agents", "2",
                                                         "--parked-fraction", "0.3", "--buffer-size", "200"]))
    assert cfg.parked_agents == 2 and cfg.parked_fraction == 0.3
    cfg.validate()
    model = build_model(cfg)
    env = model.get_env().envs[0].unwrapped
    assert env.parked_agents == 2 and env.parked_fraction == 0.3
    # relabelled goals come from achieved goals drawn without the parked agents, stored apart
    assert not model.replay_buffer.achieved_goal_is_observation
    ckpt = str(tmp_path / "plain.zip")
    build_model(TrainConfig(env_id="SafeApartment0-v0", buffer_size=200)).save(ckpt)
    cfg.init = ckpt
    resumed = build_model(cfg)
    assert resumed.get_env().envs[0].unwrapped.parked_agents == 2
    assert not resumed.replay_buffer.achieved_goal_is_observation
    assert build_model(TrainConfig(env_id="SafeApartment0-v0", init=ckpt, buffer_size=200)
                       ).replay_buffer.achieved_goal_is_observation
    with pytest.raises(ValueError, match="parked_agents"):
        TrainConfig(parked_agents=-1).validate()
    with pytest.raises(ValueError, match="parked_fraction"):
        TrainConfig(parked_agents=2, parked_fraction=2.0).validate()


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.0, 0.7])
def test_a_killed_run_resumes_to_one_run_on_one_map(tmp_path, delay):
    import os
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    args = ["train", "--out", str(out), "--replay-save-freq", "100", *[a if a != "300" else "600" for a in TINY]]
    runner = "import sys; from baselines.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen([sys.executable, "-c", runner, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    t0 = time.monotonic()
    while not (out / "resume" / "state.json").exists() and proc.poll() is None and time.monotonic() - t0 < 300:
        time.sleep(0.02)
    time.sleep(delay)
    proc.kill()  # SIGKILL: no chance to clean up
    proc.wait()
    assert proc.returncode != 0, "the run ended before it was killed"
    assert main([*args, "--resume"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env_id"] == "SafeCenterDot-v0" and summary["timesteps"] == 600
    assert summary["gradient_steps"] == 600 - 100  # one per step after learning_starts, as without the kill
    evals = [json.loads(line)["timesteps"] for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert evals == [150, 300, 450, 600]
    model = SafeGoalTD3.load(out / "model.zip")
    assert model.env_id == "SafeCenterDot-v0" and model.num_timesteps == 600
    assert not [p.name for p in out.rglob(".*tmp*")]  # no temporary file left behind by the finished run
