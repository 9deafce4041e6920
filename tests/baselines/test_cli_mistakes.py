"""Every mistake gets its message before any work: exit code 2, no traceback, nothing left behind."""
import csv
import io
import sys

import pytest

import agents
import baselines.metrics
from baselines.cli import build_parser, main
from baselines.output import RowWriter, check_output_dir


def _no_models(*args, **kwargs):
    raise AssertionError("the command loaded a checkpoint before checking its arguments")


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_bench_env_names_an_unknown_id_and_a_crowd_that_cannot_fit(capsys):
    assert main(["bench-env", "Nope-v0"]) == 2
    err = _err(capsys)
    assert "unknown env id 'Nope-v0'" in err and "SafeCentralObstacle-v0" in err
    assert main(["bench-env", "SafeCenterDot-v0", "--agents", "2", "5000", "--steps", "10"]) == 2
    assert "n_agents=5000 cannot fit" in _err(capsys)


def test_train_names_an_unknown_env_and_leaves_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--env", "Nope-v0", "--timesteps", "10", "--out", str(out)]) == 2
    assert "unknown env id 'Nope-v0'" in _err(capsys)
    assert not out.exists()


def test_train_into_an_unwritable_folder_is_a_message(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert main(["train", "--env", "SafeCenterDot-v0", "--timesteps", "10", "--out", str(blocker / "run")]) == 2
    assert "a-file" in _err(capsys)


def test_evaluate_refuses_more_agents_than_fit_before_loading_anything(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(agents, "load_pretrained", _no_models)
    out = tmp_path / "out"
    assert main(["evaluate", "--agents", "5000", "--out", str(out)]) == 2
    err = _err(capsys)
    assert "--agents 5000" in err and "graph nodes" in err
    assert main(["evaluate", "--agents", "900", "--nodes", "1000", "--out", str(out)]) == 2
    assert "--agents 900: n_agents=900 cannot fit" in _err(capsys)
    assert not out.exists()


@pytest.mark.parametrize("protocol", ["strict", "paper"])
def test_evaluate_checks_the_output_folder_before_any_work(tmp_path, capsys, monkeypatch, protocol):
    monkeypatch.setattr(agents, "load_pretrained", _no_models)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    argv = ["evaluate", "--protocol", protocol, "--env", "SafeCenterDot-v0", "--out", str(blocker / "results")]
    assert main(argv) == 2
    err = _err(capsys)
    assert "--out" in err and "not a writable folder" in err


def test_check_output_dir_removes_what_it_created_when_it_fails(tmp_path):
    made = check_output_dir(tmp_path / "x" / "y")
    assert made.is_dir()
    blocker = tmp_path / "f"
    blocker.write_text("")
    with pytest.raises(ValueError, match="is a file"):
        check_output_dir(blocker)
    with pytest.raises(ValueError, match="not a writable folder"):
        check_output_dir(blocker / "sub" / "deeper")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f", "x"]


def test_row_writer_puts_each_row_on_disk_at_once(tmp_path):
    path = tmp_path / "runs.csv"
    w = RowWriter(path)
    w.write({"method": "sorb", "success": True})
    assert list(csv.DictReader(path.open())) == [{"method": "sorb", "success": "True"}]
    w.write({"method": "ours", "success": False})
    assert [r["method"] for r in csv.DictReader(path.open())] == ["sorb", "ours"]
    w.close()


def test_evaluate_keeps_the_rows_of_a_run_that_fails_later(tmp_path, capsys, monkeypatch):
    def broken(rows):
        raise ValueError("aggregation failed")

    monkeypatch.setattr(baselines.metrics, "aggregate", broken)
    code = main(["evaluate", "--agents", "1", "--problems", "2", "--difficulty", "easy", "--methods", "sorb",
                 "--nodes", "150", "--no-figure", "--no-progress", "--out", str(tmp_path)])
    assert code == 2 and "aggregation failed" in _err(capsys)
    rows = list(csv.DictReader((tmp_path / "runs.csv").open()))
    assert [(r["method"], r["problem"]) for r in rows] == [("sorb", "0"), ("sorb", "1")]


def test_a_bare_evaluate_is_a_small_run_and_every_help_shows_defaults(capsys):
    args = build_parser().parse_args(["evaluate"])
    assert args.agents == [1, 5] and args.problems == 5
    helps = {}
    for command in ("evaluate", "train", "bench-env", "mapf"):
        with pytest.raises(SystemExit):
            build_parser().parse_args([command, "--help"])
        helps[command] = " ".join(capsys.readouterr().out.split())
    ev_help = helps["evaluate"]
    assert "(default: SafeCentralObstacle-v0)" in ev_help and "the paper's Table I: 1 5 10 20" in ev_help
    assert "(default: results)" in ev_help and "(default: ['easy', 'medium', 'hard'])" in ev_help
    assert "--seed SEED seed of the resets and the random actions (default: 0)" in helps["bench-env"]
    assert "--timesteps TIMESTEPS environment steps of this stage (default: 30000)" in helps["train"]
    assert "--time-limit S seconds (default 60)" in helps["mapf"]  # stated in words: not repeated


def test_the_small_run_note_says_what_the_full_table_takes():
    from baselines.commands.evaluate import _small_run_note

    args = build_parser().parse_args(["evaluate"])
    assert "1126 s" in _small_run_note(args)
    assert _small_run_note(build_parser().parse_args(["evaluate", "--problems", "50"])) == ""


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bars_are_drawn_only_on_a_terminal(monkeypatch):
    from baselines.cli import show_progress
    from baselines.commands.train import config_from_args

    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a log file or a pipe
    assert not show_progress() and config_from_args(build_parser().parse_args(["train"])).progress_bar is False
    monkeypatch.setattr(sys, "stderr", _Terminal())
    assert show_progress() and not show_progress(disabled=True)
    assert config_from_args(build_parser().parse_args(["train"])).progress_bar is True
    assert config_from_args(build_parser().parse_args(["train", "--no-progress"])).progress_bar is False
