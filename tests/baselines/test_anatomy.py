"""Failure anatomy: each reason on scripted stand-in runs, the per-cell summary, the table and the figure."""
import math

import numpy as np
import pytest

import safe_mapf_envs
from agents.search.execution.episode import Leg
from baselines.anatomy import (
    REASONS,
    FailureTracker,
    anatomy_figure,
    anatomy_table,
    classify,
    draw_anatomy,
    failure_records,
    failure_summary,
    failures_field,
    parse_failures_field,
)
from baselines.methods import METHODS, execute


def euclid(a, b):
    return float(np.linalg.norm(np.asarray(a, float) - np.asarray(b, float)))


def scripted(paths, holds=None, contacts=None, window=10):
    """A tracker fed ``len(paths[0]) - 1`` steps of scripted holds and contacts."""
    names = [f"agent_{i}" for i in range(len(paths))]
    tracker = FailureTracker(names, step_length=1.0, touch=1.5, window=window)
    steps = len(paths[0]) - 1
    for t in range(steps):
        holding = {a: (holds or {}).get(a, [None] * steps)[t] for a in names}
        infos = {a: {"collided_with": (contacts or {}).get(a, [[]] * steps)[t]} for a in names}
        tracker.step(holding, infos, names)
    return tracker, np.stack([np.asarray(p, float) for p in paths], axis=1)


def test_classify_tests_the_reasons_in_order():
    assert classify(False, 1.0, 50.0, 1.0, 10, True) == "never_planned"
    assert classify(True, 0.6, 50.0, 1.0, 10, True) == "deadlock"
    assert classify(True, 0.4, 2.0, 1.0, 10, True) == "out_of_time"
    assert classify(True, 0.4, 1.9, 1.0, 10, True) == "blocked_by_parked"
    assert classify(True, 0.4, 1.9, 1.0, 10, False) == "stuck_on_leg"


def test_each_reason_from_a_scripted_run():
    t = 20
    moving = [[float(i), 0.0] for i in range(t + 1)]                 # closes in on (30, 0) at full speed
    stuck = [[0.0, 10.0]] * (t + 1)                                  # never moves
    waiting = [[0.0, 20.0]] * (t + 1)                                # stands for agent_0 all the time
    beside_parked = [[0.0, 30.0]] * (t + 1)                          # stalls next to agent_4
    parked = [[1.0, 30.0]] * (t + 1)                                 # parked from step 1
    tracker, pos = scripted([moving, stuck, waiting, beside_parked, parked],
                            holds={"agent_2": ["yield:agent_0"] * t})
    goals = np.array([[30.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 40.0], [1.0, 30.0]])
    reached = np.array([False, False, False, False, True])
    parked_at = np.array([-1, -1, -1, -1, 1])
    legs = {"agent_1": Leg(source=3, target=7, predicted=4.0, started=0)}
    nodes = np.zeros((10, 2))
    nodes[3], nodes[7] = [0.0, 10.0], [0.0, 4.0]
    out = tracker.diagnose(pos, goals, reached, parked_at, euclid, legs=legs, node_positions=nodes,
                           escapes={"agent_1": 3})
    by = {f.agent: f for f in out}
    assert set(by) == {"agent_0", "agent_1", "agent_2", "agent_3"}  # the parked agent arrived
    assert by["agent_0"].reason == "out_of_time" and by["agent_0"].progress == pytest.approx(10.0)
    assert by["agent_2"].reason == "deadlock" and by["agent_2"].blocker == "agent_0"
    assert by["agent_2"].held_share == 1.0
    assert by["agent_3"].reason == "blocked_by_parked" and by["agent_3"].blocker == "agent_4"
    f = by["agent_1"]
    assert f.reason == "stuck_on_leg" and f.escapes == 3
    assert (f.edge_source, f.edge_target, f.predicted_length) == (3, 7, 4.0)
    assert f.true_length == pytest.approx(6.0) and f.to_target == pytest.approx(6.0)
    assert f.to_goal == pytest.approx(10.0)
    # without a plan every failure is "never planned"
    again = tracker.diagnose(pos, goals, reached, parked_at, euclid, planned=False)
    assert {f.reason for f in again} == {"never_planned"}


def test_a_leg_from_the_start_is_measured_from_where_the_route_began():
    path = [[5.0, 0.0]] * 3 + [[6.0, 0.0]] * 20
    tracker, pos = scripted([path])
    leg = Leg(source=None, target=None, predicted=math.nan, started=5)  # replanned at step 5, last leg
    (f,) = tracker.diagnose(pos, np.array([[6.0, 8.0]]), np.array([False]), np.array([-1]), euclid,
                            legs={"agent_0": leg})
    assert (f.edge_source, f.edge_target) == (-1, -1)
    assert f.true_length == pytest.approx(8.0)  # from (6, 0), where it stood at step 5, to its goal


def test_pushing_against_a_live_agent_is_a_deadlock():
    a = [[0.0, 0.0]] * 15
    b = [[1.0, 0.0]] * 15
    tracker, pos = scripted([a, b], contacts={"agent_0": [["agent_1"]] * 14, "agent_1": [["agent_0"]] * 14})
    out = tracker.diagnose(pos, np.array([[9.0, 0.0], [-9.0, 0.0]]), np.array([False, False]),
                           np.array([-1, -1]), euclid)
    assert [(f.reason, f.blocker) for f in out] == [("deadlock", "agent_1"), ("deadlock", "agent_0")]


def test_summary_table_and_figure(tmp_path):
    rows = [
        {"method": "ours", "agents": 5, "difficulty": "hard", "problem": 0, "failures": "agent_1:stuck_on_leg"},
        {"method": "ours", "agents": 5, "difficulty": "hard", "problem": 1,
         "failures": "agent_0:deadlock;agent_3:stuck_on_leg"},
        {"method": "ours", "agents": 5, "difficulty": "hard", "problem": 2, "failures": ""},
        {"method": "ours", "agents": 1, "difficulty": "easy", "problem": 0, "failures": float("nan")},  # read from CSV
    ]
    assert parse_failures_field(rows[1]["failures"]) == ["deadlock", "stuck_on_leg"]
    summary = failure_summary(rows)
    assert [(c["difficulty"], c["agents"]) for c in summary] == [("easy", 1), ("hard", 5)]
    hard = summary[1]
    assert (hard["runs"], hard["failed_runs"], hard["failed_agents"]) == (3, 2, 3)
    assert (hard["stuck_on_leg"], hard["deadlock"], hard["never_planned"]) == (2, 1, 0)
    table = anatomy_table(summary)
    assert "| ours | Hard | 5 | 2/3 | 3 |" in table and "2 (67%)" in table
    assert all(r in table.splitlines()[0] for r in REASONS)
    png = anatomy_figure(summary, tmp_path / "a.png", title="test")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_the_figure_shows_every_reason_and_says_when_a_method_has_no_failures():
    import matplotlib.pyplot as plt

    all_reasons = ";".join(f"agent_{i}:{r}" for i, r in enumerate(REASONS))
    rows = [{"method": m, "agents": k, "difficulty": d, "problem": 0, "failures": f}
            for m, f in (("ours", all_reasons), ("sgm", "")) for k, d in ((1, "easy"), (5, "hard"))]
    fig = draw_anatomy(failure_summary(rows), title="test")
    try:
        fig.canvas.draw()
        (legend,) = fig.legends
        labels = [t.get_text() for t in legend.get_texts()]
        assert sorted(labels) == sorted(r.replace("_", " ") for r in REASONS) and "stuck on leg" in labels
        # the whole legend lies inside the saved image (no entry cut off at its edge)
        box, page = legend.get_window_extent(), fig.bbox
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1
        ours, sgm = fig.axes
        assert ours.get_ylim()[0] == 0 and ours.get_ylim()[1] >= len(REASONS)
        assert not [t for t in ours.texts if t.get_text() == "no failures"]
        # a method without a failed agent: a note and an axis from 0, not a band around it
        assert [t.get_text() for t in sgm.texts] == ["no failures"]
        assert sgm.get_ylim() == (0.0, 1.0)
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="no evaluation cells"):
        draw_anatomy([])


def test_an_execution_records_why_agents_failed(stand_in_models):
    """A straight-line policy against the central block gets stuck there; the reason says so, and the
    row form lists exactly the agents that did not arrive."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2, max_cycles=60)
    starts = np.array([[4.0, 27.5], [40.0, 50.0]])
    goals = np.array([[51.0, 27.5], [44.0, 50.0]])
    ex = execute(env, METHODS["unconstrained_policy"], stand_in_models, None, starts, goals)
    env.close()
    assert list(ex.reached) == [False, True]
    (f,) = ex.failures
    assert f.agent == "agent_0" and f.reason == "stuck_on_leg" and f.to_goal > 10
    assert failures_field(ex.failures) == "agent_0:stuck_on_leg"
    rec = failure_records({"method": "m", "agents": 2, "difficulty": "easy", "problem": 4}, ex.failures)
    assert rec[0]["method"] == "m" and rec[0]["reason"] == "stuck_on_leg" and rec[0]["agent"] == "agent_0"


def test_the_anatomy_script_compares_folders(tmp_path, run_example):
    import csv

    fields = ["method", "agents", "difficulty", "problem", "success", "failures"]
    for name, failures in (("before", ["agent_1:stuck_on_leg", "agent_0:deadlock;agent_2:stuck_on_leg"]),
                           ("after", ["", "agent_2:stuck_on_leg"])):
        (tmp_path / name).mkdir()
        with open(tmp_path / name / "runs.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=fields)
            w.writeheader()
            for i, text in enumerate(failures):
                w.writerow({"method": "ours", "agents": 5, "difficulty": "hard", "problem": i,
                            "success": not text, "failures": text})
    code, captured = run_example("failure_anatomy.py", str(tmp_path / "before"), str(tmp_path / "after"), "--labels",
                                 "before", "after", "--figure", str(tmp_path / "a.png"), "--problems", "2")
    assert code == 0
    out = captured.out
    assert "## before: 0/2 runs succeeded; 3 agents failed: deadlock 1 (33%), stuck_on_leg 2 (67%)" in out
    assert "## after: 1/2 runs succeeded; 1 agents failed: stuck_on_leg 1 (100%)" in out
    assert (tmp_path / "a.png").exists()
