"""``safe-mapf train-marl``: a tiny run end to end, TensorBoard, and clear errors before any work."""
import json
import os

import pytest

from baselines.cli import main

TINY = ["--env", "SafeCenterDot-v0", "--agents", "2", "--timesteps", "128", "--n-envs", "2", "--n-steps", "16",
        "--batch-size", "32", "--n-epochs", "1", "--max-cycles", "10", "--eval-freq", "0", "--eval-episodes", "1",
        "--net-arch", "8"]


def test_train_marl_writes_the_run_and_tensorboard(tmp_path, capsys):
    out, tb = tmp_path / "run", tmp_path / "tb"
    assert main(["train-marl", "--algo", "mappo-lag", *TINY, "--out", str(out), "--tensorboard", str(tb),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["algo"] == "mappo-lag" and summary["timesteps"] >= 128 and "lagrange_multiplier" in summary
    assert {"model.pt", "model.json", "checkpoint.pt", "checkpoint.json", "config.json", "evaluations.jsonl",
            "summary.json"} <= set(os.listdir(out))
    assert any(name.startswith("events.out.tfevents") for _, _, files in os.walk(tb) for name in files)
    # --seeds: one run per seed, each in its own folder
    assert main(["train-marl", "--algo", "ippo", *TINY, "--seeds", "1", "2", "--out", str(tmp_path / "many")]) == 0
    assert "ippo: 128 agent steps" in capsys.readouterr().out
    assert (tmp_path / "many" / "s1" / "model.zip").exists() and (tmp_path / "many" / "s2" / "model.zip").exists()


@pytest.mark.parametrize("argv,message", [
    (["--agents", "0"], "n_agents must be an integer >= 1"),
    (["--env", "SafeApartment0-v0"], "panorama"),
    (["--env", "SafeCentralObstacel-v0"], "did you mean 'SafeCentralObstacle-v0'"),
    (["--gamma", "2"], "gamma must be"),
    (["--resume"], "nothing to resume"),
])
def test_train_marl_names_bad_input_before_any_work(argv, message, tmp_path, capsys):
    assert main(["train-marl", *TINY, "--out", str(tmp_path / "r"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "r" / "model.json").exists()


def test_train_marl_rejects_a_non_integer(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["train-marl", "--timesteps", "lots"])
    assert exc.value.code == 2 and "expected an integer, got 'lots'" in capsys.readouterr().err


def test_train_marl_checks_every_seed_folder_before_the_first_run(tmp_path, capsys):
    base = tmp_path / "many"
    (base / "s2").mkdir(parents=True)
    (base / "s2" / "checkpoint.json").write_text("{}")  # seed 2's folder already holds a run
    assert main(["train-marl", *TINY, "--seeds", "1", "2", "--out", str(base)]) == 2
    assert "is not empty (checkpoint.json)" in capsys.readouterr().err
    assert not (base / "s1").exists()
