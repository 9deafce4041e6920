"""``safe-mapf bench-env``: memory per row, the parallel env's episode length and a map file."""
import argparse
import json
import sys

import pytest

from baselines.cli import main
from baselines.commands.bench_env import run

MAP = """type octile
height 12
width 16
map
................
................
....@@....@@....
....@@....@@....
................
................
................
..@@@@....@@@@..
................
................
................
................
"""


def _run(capsys, **kwargs):
    args = argparse.Namespace(env_id="SafeCentralObstacle-v0", steps=20, agents=None, seed=0, json=True,
                              max_cycles=None, map_file=None)
    for k, v in kwargs.items():
        setattr(args, k, v)
    assert run(args) == 0
    out = capsys.readouterr().out
    return json.loads(out) if args.json else out


def test_every_row_reports_the_memory_of_the_process(capsys):
    rows = _run(capsys, agents=[2, 6])
    for r in rows:
        if sys.platform.startswith("linux"):
            assert 0 < r["rss_mb"] <= r["peak_rss_mb"]
        assert r["peak_rss_mb"] > 0
    out = _run(capsys, json=False)
    assert "timed 20 steps (20 agent-steps," in out and "MB resident" in out and "MB peak" in out


def test_max_cycles_sets_the_episode_length_of_the_parallel_env(capsys):
    rows = _run(capsys, agents=[3], steps=12, max_cycles=5)
    assert rows["resets"] == 2 and rows["max_cycles"] == 5  # steps 1-5, reset, 7-11, reset, 12
    assert rows["agent_steps"] <= 3 * 12
    with pytest.raises(ValueError, match="give --agents"):
        _run(capsys, max_cycles=5)
    with pytest.raises(ValueError, match="--max-cycles must be >= 1"):
        _run(capsys, agents=[2], max_cycles=0)


def test_a_map_file_replaces_the_map_of_the_id(capsys, tmp_path):
    path = tmp_path / "two-rooms.map"
    path.write_text(MAP)
    single = _run(capsys, map_file=str(path))
    assert single["env_id"] == "SafeTwo-rooms-v0" and single["map"] == str(path)
    multi = _run(capsys, map_file=str(path), agents=[4], steps=5)
    assert multi["env_id"] == "SafeTwo-rooms-v0" and multi["agents"] == 4


def test_a_missing_or_malformed_map_file_exits_with_code_2(capsys, tmp_path):
    assert main(["bench-env", "SafeCentralObstacle-v0", "--map", str(tmp_path / "missing.map")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.map"
    bad.write_text("not a map\n")
    assert main(["bench-env", "SafeCentralObstacle-v0", "--agents", "2", "--map", str(bad)]) == 2
    assert "bad.map" in capsys.readouterr().err
