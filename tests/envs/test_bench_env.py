"""``safe-mapf bench-env`` times the steps it is asked to time and says what it timed."""
import argparse
import json

import pytest

from baselines.commands.bench_env import run


def _run(capsys, **kwargs):
    args = argparse.Namespace(env_id="SafeCentralObstacle-v0", steps=45, agents=None, seed=0, json=True)
    for k, v in kwargs.items():
        setattr(args, k, v)
    assert run(args) == 0
    out = capsys.readouterr().out
    return json.loads(out) if args.json else out


def test_single_agent_times_the_requested_steps_with_resets(capsys):
    row = _run(capsys)
    assert row["steps"] == row["agent_steps"] == 45
    assert row["resets"] >= 2  # episodes of at most 20 steps were reset inside the timed loop


def test_parallel_times_the_requested_steps_for_every_agent_count(capsys):
    rows = _run(capsys, steps=30, agents=[1, 4])
    assert [r["steps"] for r in rows] == [30, 30]
    assert [r["agents"] for r in rows] == [1, 4]
    for r in rows:
        assert r["steps"] <= r["agent_steps"] <= r["steps"] * r["agents"]
        assert r["agent_steps_per_s"] == pytest.approx(r["agent_steps"] / r["seconds"])


def test_text_output_says_what_was_timed(capsys):
    out = _run(capsys, steps=25, json=False)
    assert "timed 25 steps (25 agent-steps," in out and "resets included" in out
    with pytest.raises(ValueError, match="--agents"):
        _run(capsys, agents=[0])
