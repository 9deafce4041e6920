"""agents.evaluation.run_routes: driving a route of waypoints open loop, and examples/bench_routes.py."""
import json

import numpy as np
import pytest

from agents import load_pretrained
from agents.evaluation import run_routes

ENV = "SafeCentralObstacle-v0"


class StandStill:
    """A model that never moves and whose critic calls every goal 0 steps away."""

    def predict(self, obs, deterministic=True):
        return np.zeros((len(obs["observation"]), 2), np.float32), None

    def distance(self, obs, goals, aggregate="max"):
        return np.zeros(len(obs))


def test_the_critic_rule_moves_on_when_the_critic_says_so_and_counts_where():
    route = np.array([[2.0, 2.0], [4.0, 2.0], [2.0, 5.0], [2.0, 12.0]])
    out = run_routes(StandStill(), ENV, [route], advance="critic", max_steps=10)
    # one waypoint per step, never the goal: stuck on the last leg, both waypoints passed from the start
    assert not out["success"][0] and out["steps"][0] == 10
    assert out["hops"][0] == 3 and out["advanced"][0] == 2 and out["stuck_at"][0] == 2
    assert out["pass_distance"][0] == pytest.approx((2.0 + 3.0) / 2)


def test_the_reach_rule_waits_for_the_agent_to_be_there():
    route = np.array([[2.0, 2.0], [4.0, 2.0], [2.0, 12.0]])
    out = run_routes(StandStill(), ENV, [route], advance="reach", max_steps=5)
    assert out["advanced"][0] == 0 and out["stuck_at"][0] == 0 and np.isnan(out["pass_distance"][0])


def test_a_trained_agent_drives_routes_around_the_obstacle():
    model = load_pretrained(ENV, kind="constrained")
    routes = [np.array([[2.0, 2.0], [5.0, 3.0], [8.0, 2.0], [12.0, 3.0]]),
              np.array([[2.0, 2.0], [2.0, 7.5], [3.0, 12.0], [12.0, 12.0]]),
              np.array([[12.0, 2.0], [12.0, 12.0]])]
    threshold = 1.0  # the env's goal_threshold
    for advance in ("critic", "reach"):
        out = run_routes(model, ENV, routes, advance=advance)
        assert out["success"].all() and (out["stuck_at"] == -1).all()
        assert (out["advanced"] == out["hops"] - 1).all() and (out["cost"] >= 0).all()
        if advance == "reach":
            assert np.nanmax(out["pass_distance"]) <= threshold
    short = run_routes(model, ENV, routes[:1], max_steps=3)  # too few steps to arrive
    assert not short["success"][0] and 0 <= short["stuck_at"][0] < 3


@pytest.mark.parametrize("kwargs, match", [
    (dict(advance="oracle"), "advance must be one of critic, reach"),
    (dict(max_steps=0), "max_steps and batch must be >= 1"),
])
def test_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        run_routes(StandStill(), ENV, [np.array([[2.0, 2.0], [3.0, 3.0]])], **kwargs)


def test_a_route_needs_a_start_and_a_goal():
    with pytest.raises(ValueError, match="route 1 needs a start and a goal"):
        run_routes(StandStill(), ENV, [np.array([[2.0, 2.0], [3.0, 3.0]]), np.array([[2.0, 2.0]])])
    with pytest.raises(ValueError, match="route 0 needs a start and a goal of finite positions"):
        run_routes(StandStill(), ENV, [np.array([[2.0, np.nan], [3.0, 3.0]])])


def test_the_benchmark_script_writes_a_row_per_agent_and_difficulty(run_example, tmp_path):
    code, out = run_example("bench_routes.py", "--env", ENV, "--routes", "3", "--nodes", "150",
                            "--difficulties", "easy", "medium", "--out", str(tmp_path))
    assert code == 0
    rows = json.loads((tmp_path / "routes.json").read_text())["rows"]
    assert [(r["difficulty"], r["agent"]) for r in rows] == [
        ("easy", "unconstrained"), ("easy", "constrained"), ("medium", "unconstrained"), ("medium", "constrained")]
    for r in rows:
        assert r["routes"] == 3 and r["hops"] == round(3 * r["mean_hops"])
        assert 0 <= r["route_success_critic"] <= 1 and 0 <= r["hop_success"] <= 1
        assert r["failed_first"] + r["failed_middle"] + r["failed_last"] == round(3 * (1 - r["route_success_critic"]))
    table = (tmp_path / "routes.md").read_text()
    assert "| medium | constrained | 3 (" in table and table in out.out
