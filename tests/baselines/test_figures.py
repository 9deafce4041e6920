"""The trajectory figure and the execution frames speak one marker legend."""
import matplotlib.axes
import matplotlib.figure
import numpy as np

import baselines.figures as figures
import safe_mapf_envs
from baselines.evaluation import EvaluationSetup
from baselines.methods import METHODS


def test_the_figure_and_the_frames_share_one_marker_legend(stand_in_models, tmp_path, monkeypatch):
    import gymnasium as gym

    from agents.self_sampling import observations_at

    env = gym.make("SafeCentralObstacle-v0")
    states = env.unwrapped.sample_states(120, np.random.default_rng(1))
    obs = observations_at(env, states)
    D, C = stand_in_models["unconstrained"].pairwise(obs, obs)
    setup = EvaluationSetup("SafeCentralObstacle-v0", stand_in_models, states, obs, D, C)

    titles, markers = [], []
    real_title, real_plot = matplotlib.figure.Figure.suptitle, matplotlib.axes.Axes.plot
    monkeypatch.setattr(matplotlib.figure.Figure, "suptitle",
                        lambda self, t, **kw: titles.append(" ".join(t.split())) or real_title(self, t, **kw))
    monkeypatch.setattr(matplotlib.axes.Axes, "plot",
                        lambda self, *a, **kw: markers.append(a[-1]) or real_plot(self, *a, **kw))
    figures.trajectory_figure(setup, [METHODS["sorb"]], tmp_path / "f.png", agent_counts=(2,), difficulty="easy")
    assert figures.MARKER_LEGEND in titles[0]
    assert {"D", "x", "o"} <= set(markers) and "*" not in markers  # diamonds: waypoints, x: goals, as drawn below

    lines = []
    monkeypatch.setattr(figures, "caption", lambda img, ls, **kw: lines.append(ls) or img)
    par = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1)
    traj = np.array([[[5.0, 5.0]], [[6.0, 5.0]]])
    figures.execution_frames(par.field, traj, np.array([[6.0, 5.0]]), par.goal_threshold)
    assert all(figures.MARKER_LEGEND in ls[1] for ls in lines) and len(lines) == 2
