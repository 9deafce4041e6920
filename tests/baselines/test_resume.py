"""Output folders of ``safe-mapf evaluate``: refused when used, --overwrite, --resume, interrupts and kills."""
import csv
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from baselines.cli import main, resume_command

SMALL = ["--agents", "1", "2", "--problems", "2", "--difficulty", "easy", "--nodes", "150", "--methods",
         "unconstrained_policy", "sorb", "--no-figure", "--no-progress", "--seed", "3", "--max-cycles", "60"]
#: the command as a terminal runs it: Ctrl-C raises KeyboardInterrupt even where the test itself was started in
#: the background (a non-interactive shell starts background jobs with SIGINT ignored, and children inherit that)
RUNNER = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
          "from baselines.cli import main; sys.exit(main(sys.argv[1:]))")


def rows(path):
    """The rows of runs.csv, timings aside."""
    with open(path, newline="") as f:
        return [{k: v for k, v in r.items() if k != "planning_time"} for r in csv.DictReader(f)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "full"
    assert main(["evaluate", *SMALL, "--out", str(out)]) == 0
    return out


def _spawn(args, **kw):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-c", RUNNER, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, **kw)


def _freeze_at_rows(path, n, proc, limit=120.0):
    """Stop the process (SIGSTOP) as soon as ``path`` has ``n`` rows (header aside): its rows come
    tens of milliseconds apart, so it must be frozen at once to be caught part of the way."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit and proc.poll() is None:
        if path.exists() and path.read_text().count("\n") > n:
            proc.send_signal(signal.SIGSTOP)
            return
        time.sleep(0.001)


def test_a_used_folder_is_refused_and_overwrite_removes_only_what_evaluate_wrote(reference, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["evaluate", *SMALL, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not empty (notes.txt)" in err and "--resume" in err and "--overwrite" in err
    assert sorted(os.listdir(out)) == ["notes.txt"]  # nothing written
    (out / "figure.png").write_bytes(b"an earlier run's figure")
    (out / "runs.csv").write_text("method\nold\n")
    assert main(["evaluate", *SMALL, "--out", str(out), "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "mine"  # not ours: kept
    assert not (out / "figure.png").exists()  # an earlier run's file this run does not write: gone
    assert rows(out / "runs.csv") == rows(reference / "runs.csv")
    assert main(["evaluate", *SMALL, "--out", str(out), "--resume", "--overwrite"]) == 2
    assert "not both" in capsys.readouterr().err


def test_resume_refuses_other_settings_naming_them(reference, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["evaluate", *SMALL, "--out", str(out)]) == 0
    before = (out / "runs.csv").read_text()
    other = [a if a != "3" else "4" for a in SMALL]  # --seed 4
    assert main(["evaluate", *other, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "--seed: 3 there, 4 now" in err
    assert main(["evaluate", *SMALL, "--protocol", "paper", "--out", str(out), "--resume"]) == 2
    assert "--protocol" in capsys.readouterr().err
    assert (out / "runs.csv").read_text() == before
    assert main(["evaluate", *SMALL, "--out", str(tmp_path / "new"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err


def test_resume_of_a_finished_run_runs_nothing_again_and_gives_the_same_folder(reference, tmp_path):
    out = tmp_path / "out"
    assert main(["evaluate", *SMALL, "--out", str(out)]) == 0
    assert main(["evaluate", *SMALL, "--out", str(out), "--resume"]) == 0
    assert (out / "runs.csv").read_text() == (tmp_path / "out" / "runs.csv").read_text()
    assert rows(out / "runs.csv") == rows(reference / "runs.csv")
    record = json.loads((out / "run.json").read_text())
    assert record["settings"]["seed"] == 3 and len(record["resumed"]) == 1


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_an_interrupted_or_killed_run_resumes_to_the_rows_of_an_uninterrupted_one(reference, tmp_path, sig):
    out = tmp_path / "out"
    args = ["evaluate", *SMALL, "--out", str(out)]
    proc = _spawn(args)
    _freeze_at_rows(out / "runs.csv", 1, proc)
    partial = rows(out / "runs.csv")
    proc.send_signal(sig)
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=120)
    assert rows(out / "runs.csv") == partial  # nothing written after the signal
    assert 1 <= len(partial) < len(rows(reference / "runs.csv"))  # stopped part of the way
    assert partial == rows(reference / "runs.csv")[:len(partial)]
    if sig == signal.SIGINT:
        assert proc.returncode == 130
        lines = [line for line in err.splitlines() if line.strip()]
        assert lines[-1].startswith("safe-mapf evaluate: interrupted; kept ") and "Traceback" not in err
        assert lines[-1].endswith(resume_command(args))
    assert main([*args, "--resume"]) == 0
    assert rows(out / "runs.csv") == rows(reference / "runs.csv")
    for name in ("failures.csv", "anatomy.csv", "anatomy.md"):
        assert (out / name).read_text() == (reference / name).read_text(), name


def test_a_row_cut_off_by_a_kill_is_run_again(reference, tmp_path):
    out = tmp_path / "out"
    assert main(["evaluate", *SMALL, "--out", str(out)]) == 0
    text = (out / "runs.csv").read_text()
    lines = text.splitlines(keepends=True)
    (out / "runs.csv").write_text("".join(lines[:3]) + lines[3][:10])  # two rows whole, the third cut off
    assert main(["evaluate", *SMALL, "--out", str(out), "--resume"]) == 0
    assert rows(out / "runs.csv") == rows(reference / "runs.csv")


def test_checks_come_before_any_work_and_name_the_flag(tmp_path, capsys, monkeypatch):
    from baselines.evaluation import EvaluationSetup

    def no_work(*args, **kwargs):
        raise AssertionError("the graph was built before the checks refused the command")

    monkeypatch.setattr(EvaluationSetup, "build", no_work)
    assert main(["evaluate", "--agents", "300", "--out", str(tmp_path / "a")]) == 2
    assert "--agents 300" in capsys.readouterr().err
    assert main(["evaluate", "--c-max-from", str(tmp_path / "nope.json"), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "--c-max-from" in err and "no such file" in err
    (tmp_path / "garbage.json").write_text("{not json")
    assert main(["evaluate", "--c-max-from", str(tmp_path / "garbage.json"), "--out", str(tmp_path / "c")]) == 2
    assert "garbage.json" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["evaluate", "--max-cycles", "0"])
    assert "--max-cycles" in capsys.readouterr().err
    assert not any((tmp_path / d).exists() and os.listdir(tmp_path / d) for d in "abc")


def test_resume_command_adds_resume_and_drops_overwrite():
    assert resume_command(["evaluate", "--out", "a b", "--overwrite"]) == "safe-mapf evaluate --out 'a b' --resume"
    assert resume_command(["train", "--resume"]) == "safe-mapf train --resume"


def test_files_written_whole_get_the_usual_permissions(tmp_path):
    from agents.run_folder import write_atomic

    write_atomic(tmp_path / "a.txt", "text")
    (tmp_path / "b.txt").write_text("text")
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == (tmp_path / "b.txt").stat().st_mode & 0o777
