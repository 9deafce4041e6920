"""Evaluation on Ray: the rows of the serial run, and a clear error without Ray."""
import math
import os
import sys

import numpy as np
import pytest

from baselines.evaluation import EvaluationSetup, evaluate
from baselines.methods import get_methods

TIMING = {"planning_time"}


@pytest.fixture(scope="module")
def setup(stand_in_models):
    import gymnasium as gym

    env = gym.make("SafeCentralObstacle-v0")
    u = env.unwrapped
    states = u.sample_states(200, np.random.default_rng(1))
    obs = u.normalize(states).astype(np.float32)
    env.close()
    D, C = stand_in_models["unconstrained"].pairwise(obs, obs)
    return EvaluationSetup("SafeCentralObstacle-v0", stand_in_models, states, obs, D, C)


def _strip(rows):
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def test_ray_rows_are_the_serial_rows_in_the_serial_order(setup):
    ray = pytest.importorskip("ray")
    # the stand-in agent's class lives in the tests' conftest, which workers cannot import: ship it by value
    ray.cloudpickle.register_pickle_by_value(sys.modules[type(setup.models["constrained"]).__module__])
    methods = get_methods(["constrained_policy", "sorb", "ours"])
    kwargs = dict(agent_counts=[1, 3], difficulties=["easy", "hard"], n_problems=1, seed=5, progress=False,
                  max_cycles=120)
    serial_runs, ray_runs = [], []
    preset = "RAY_worker_niceness" in os.environ
    serial = evaluate(setup, methods, on_run=lambda r, p, e: serial_runs.append((p.index, e.steps)), **kwargs)
    try:
        on_ray = evaluate(setup, methods, ray="local", on_run=lambda r, p, e: ray_runs.append((p.index, e.steps)),
                          **kwargs)
        if not preset:  # a local Ray's workers run at the driver's niceness, not Ray's default 15
            worker_nice = ray.get(ray.remote(lambda: os.nice(0)).remote())
            assert worker_nice == os.nice(0), worker_nice
            assert "RAY_worker_niceness" not in os.environ  # set for ray.init only
    finally:
        ray.shutdown()
    assert len(serial) == 3 * 2 * 2
    assert _strip(on_ray) == _strip(serial)
    assert ray_runs == serial_runs  # on_run sees the runs in the rows' order, with their executions
    assert all(math.isfinite(r["planning_time"]) for r in on_ray)


def test_asking_for_ray_without_ray_names_the_extra(setup, monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    with pytest.raises(ImportError, match=r'pip install "safe-mapf\[ray\]"'):
        evaluate(setup, get_methods(["sorb"]), agent_counts=[1], difficulties=["easy"], n_problems=1,
                 progress=False, ray="local")
    from baselines.cli import main

    assert main(["evaluate", "--ray", "--problems", "1", "--agents", "1", "--out", str(tmp_path)]) == 2
    assert 'pip install "safe-mapf[ray]"' in capsys.readouterr().err
    assert not (tmp_path / "runs.csv").exists()
