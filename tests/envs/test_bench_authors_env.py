"""``examples/bench_authors_env.py`` times our env alone, or beside the authors' env of a checkout
(here a stand-in with their module layout, config file and wrapper interface) and prints the ratio."""
import textwrap

import pytest

CONFIG = """\
env:
    walls: CentralObstacle
    resize_factor: 5
    thin: false
    cost_limit: 1.0
wrappers:
    SafeGoalConditionedPointWrapper:
        prob_constraint: 0.8
        max_dist: 4
        reset_blend: 0.5
        cbfs_policy_path: "pud/envs/precompiles/central_obstacle_v2.pkl"
time_limit:
    max_episode_steps: 20
cost_function:
    name: "cosine"
    radius: 2.0
"""

WRAPPERS = '''
import numpy as np

print("[INFO] a print of theirs, on stdout")


class SafeGoalConditionedPointWrapper:
    def __init__(self, env, prob_constraint=0.8, min_dist=0, max_dist=4, min_cost=0, max_cost=1000,
                 threshold_distance=1.0):
        self.env = env


class _Env:
    """Their interface: reset() -> (obs, info); step(a) -> (obs, reward, done, info); the time
    limit resets the episode itself and says so in info["last_step"]."""

    def __init__(self, duration):
        self.duration, self.t = duration, 0

    def reset(self):
        self.t = 0
        return {"observation": np.zeros(2)}, {"cost": 0.0}

    def step(self, action):
        action += np.random.normal(0, 1.0)  # in place, as theirs
        self.t += 1
        info = {"cost": 0.0}
        if self.t >= self.duration:
            info["last_step"] = True
            self.reset()
        return {"observation": np.zeros(2)}, -1.0, False, info


def safe_env_load_fn(env_kwargs, cost_f_kwargs, max_episode_steps=0, gym_env_wrappers=(), wrapper_kwargs=(),
                     terminate_on_timeout=False):
    assert env_kwargs["walls"] == "CentralObstacle" and cost_f_kwargs["name"] == "cosine"
    assert "reset_blend" not in wrapper_kwargs[0] and wrapper_kwargs[0]["max_dist"] == 4
    assert not terminate_on_timeout
    return gym_env_wrappers[0](_Env(max_episode_steps), **wrapper_kwargs[0]).env
'''


@pytest.fixture
def authors_repo(tmp_path):
    root = tmp_path / "safe-visual-mapf"
    pkg = root / "pud" / "envs" / "safe_pointenv"
    pkg.mkdir(parents=True)
    for d in (root / "pud", root / "pud" / "envs", pkg):
        (d / "__init__.py").write_text("")
    (pkg / "safe_pointenv.py").write_text("")
    (pkg / "safe_wrappers.py").write_text(textwrap.dedent(WRAPPERS))
    (root / "configs" / "pointenv").mkdir(parents=True)
    (root / "configs" / "pointenv" / "config_SafePointEnv.yaml").write_text(CONFIG)
    return root


def test_ours_alone_says_how_to_get_the_ratio(run_example):
    code, out = run_example("bench_authors_env.py", "--steps", "30", "--repeats", "1")
    assert code == 0
    assert "SafeCentralObstacle-v0 (gymnasium.make, default wrappers):" in out.out
    assert "pass --authors-repo DIR" in out.out and "ratio" not in out.out.split("for the ratio")[0]


def test_both_alternate_and_the_ratio_is_of_the_medians(run_example, authors_repo):
    code, out = run_example("bench_authors_env.py", "--steps", "45", "--repeats", "2",
                            "--authors-repo", str(authors_repo))
    assert code == 0
    lines = out.out.splitlines()
    assert lines[0].startswith("theirs: SafePointEnv {'walls': 'CentralObstacle'")
    assert lines[1].startswith("repetition 1: ours") and "theirs" in lines[1] and "(2 resets)" in lines[1]
    assert lines[2].startswith("repetition 2: ours")
    ours = float(lines[3].split(": ")[1].split(" steps/s")[0].replace(",", ""))
    theirs = float(lines[4].split(": ")[1].split(" steps/s")[0].replace(",", ""))
    assert lines[5].startswith("ratio ours / theirs: ") and lines[5].endswith("x")
    ratio = float(lines[5].split(": ")[1][:-1])
    assert ratio == pytest.approx(ours / theirs, rel=0.01, abs=0.06)  # of the medians printed, rounded


def test_a_folder_that_is_not_their_code_is_refused(run_example, tmp_path):
    code, _ = run_example("bench_authors_env.py", "--steps", "5", "--authors-repo", str(tmp_path))
    assert "not a checkout of the authors' code" in str(code)
