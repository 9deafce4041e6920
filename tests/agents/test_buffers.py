"""The goal-relabelling cost replay buffer: stored costs, future goals, recomputed termination."""
import gymnasium as gym
import numpy as np
import pytest
import torch as th

import safe_mapf_envs  # noqa: F401
from agents.buffers import GoalCostReplayBuffer


@pytest.fixture(scope="module")
def env():
    return gym.make("SafeCentralObstacle-v0").unwrapped


def make_buffer(env, size=100, **kw):
    return GoalCostReplayBuffer(size, env.observation_space, env.action_space, device="cpu",
                                compute_terminated=env.compute_terminated, seed=0, **kw)


def add_episode(buf, env, positions, goal, ep_id, costs, terminated_last=False):
    """Add the transitions p[t] -> p[t+1]; action = (t, ep_id) identifies a transition."""
    pos = env.normalize(np.asarray(positions, float))
    g = env.normalize(np.asarray(goal, float))
    n = len(positions) - 1
    for t in range(n):
        obs = {"observation": pos[t][None], "achieved_goal": pos[t][None], "desired_goal": g[None]}
        nxt = {"observation": pos[t + 1][None], "achieved_goal": pos[t + 1][None], "desired_goal": g[None]}
        last = t == n - 1
        info = {"cost": costs[t], "position": np.asarray(positions[t + 1], float), "goal": np.asarray(goal, float)}
        if last and not terminated_last:
            info["TimeLimit.truncated"] = True
        buf.add(obs, nxt, np.array([[t / 10.0, ep_id / 10.0]], np.float32), np.array([-1.0]),
                np.array([last]), [info])


def ids(samples):
    a = samples.actions.numpy()
    return np.rint(a[:, 0] * 10).astype(int), np.rint(a[:, 1] * 10).astype(int)


def test_costs_and_original_goals_without_relabelling(env):
    buf = make_buffer(env, her_ratio=0.0)
    path = [(5.0, 5.0), (6.0, 5.0), (7.0, 5.0), (8.0, 5.0)]
    add_episode(buf, env, path, (8.5, 5.0), ep_id=1, costs=[0.1, 0.2, 0.3], terminated_last=True)
    s = buf.sample(64)
    t, ep = ids(s)
    assert set(ep) == {1}
    np.testing.assert_allclose(s.costs.numpy(), np.array([0.1, 0.2, 0.3], np.float32)[t])
    np.testing.assert_allclose(s.observations["desired_goal"].numpy(), np.tile(env.normalize((8.5, 5.0)), (64, 1)))
    # only the last step terminated (reached the goal); stored dones are used as they are
    np.testing.assert_array_equal(s.dones.numpy(), (t == 2).astype(np.float32))


def test_truncation_is_not_termination(env):
    buf = make_buffer(env, her_ratio=0.0)
    add_episode(buf, env, [(5.0, 5.0), (6.0, 5.0), (7.0, 5.0)], (30.0, 5.0), ep_id=1, costs=[0, 0])
    assert buf.sample(32).dones.sum() == 0


def test_future_relabelling_uses_later_states_and_recomputes_dones(env):
    buf = make_buffer(env, her_ratio=1.0)
    path = [(5.0, 5.0), (7.0, 5.0), (9.0, 5.0), (11.0, 5.0), (13.0, 5.0)]
    add_episode(buf, env, path, (50.0, 50.0), ep_id=1, costs=[0, 0, 0, 0])
    s = buf.sample(512)
    t, _ = ids(s)
    goals = env.denormalize(s.observations["desired_goal"].numpy())
    nxt = np.asarray(path, float)[1:]
    # every goal is the next state of the same or a later step of the episode
    k = np.argmin(np.linalg.norm(goals[:, None] - nxt[None], axis=-1), axis=1)
    np.testing.assert_allclose(goals, nxt[k], atol=1e-4)
    assert np.all(k >= t)
    assert set(zip(t, k)) == {(i, j) for i in range(4) for j in range(i, 4)}
    # done exactly where the goal is this step's own next state (neighbours are 2 units apart)
    np.testing.assert_array_equal(s.dones.numpy(), (k == t).astype(np.float32))
    np.testing.assert_allclose(s.next_observations["desired_goal"].numpy(), s.observations["desired_goal"].numpy())


def test_random_goals_come_from_the_buffer(env):
    buf = make_buffer(env, her_ratio=0.0, random_goal_ratio=1.0)
    add_episode(buf, env, [(5.0, 5.0), (6.0, 5.0), (7.0, 5.0)], (50.0, 50.0), ep_id=1, costs=[0, 0])
    add_episode(buf, env, [(40.0, 40.0), (41.0, 40.0)], (1.0, 1.0), ep_id=2, costs=[0])
    s = buf.sample(256)
    goals = {tuple(np.round(env.denormalize(g), 3)) for g in s.observations["desired_goal"].numpy()}
    assert goals == {(6.0, 5.0), (7.0, 5.0), (41.0, 40.0)}


def test_unfinished_episodes_are_not_sampled_and_empty_buffer_raises(env):
    buf = make_buffer(env)
    with pytest.raises(ValueError, match="no finished episode"):
        buf.sample(4)
    add_episode(buf, env, [(5.0, 5.0), (6.0, 5.0), (7.0, 5.0)], (50.0, 50.0), ep_id=1, costs=[0, 0])
    # a second, unfinished episode: add its first step only
    pos = env.normalize(np.array([[20.0, 5.0], [21.0, 5.0]]))
    obs = {"observation": pos[:1], "achieved_goal": pos[:1], "desired_goal": pos[1:]}
    buf.add(obs, obs, np.array([[0.0, 0.3]], np.float32), np.array([-1.0]), np.array([False]), [{"cost": 0.0}])
    assert set(ids(buf.sample(128))[1]) == {1}
    assert buf.n_complete_transitions() == 2


def test_overwritten_episodes_are_forgotten_entirely(env):
    buf = make_buffer(env, size=5, her_ratio=1.0)
    add_episode(buf, env, [(5.0, 5.0), (6.0, 5.0), (7.0, 5.0), (8.0, 5.0)], (50.0, 50.0), ep_id=1, costs=[0, 0, 0])
    add_episode(buf, env, [(20.0, 5.0), (21.0, 5.0), (22.0, 5.0), (23.0, 5.0)], (50.0, 50.0), ep_id=2,
                costs=[0, 0, 0])
    # episode 2 wrapped around onto slot 0: episode 1 is gone, episode 2 still relabels within itself
    t, ep = ids(buf.sample(256))
    assert set(ep) == {2}
    assert buf.n_complete_transitions() == 3


def test_invalid_ratios(env):
    with pytest.raises(ValueError, match="her_ratio"):
        make_buffer(env, her_ratio=1.5)
    with pytest.raises(ValueError, match="<= 1"):
        make_buffer(env, her_ratio=0.7, random_goal_ratio=0.5)


def test_rejects_non_goal_spaces():
    space = gym.spaces.Box(0, 1, (2,))
    with pytest.raises(ValueError, match="Dict"):
        GoalCostReplayBuffer(10, space, space)


def test_buffer_arrays_round_trip_and_shared_achieved_goal(tmp_path):
    env = gym.make("SafeApartment0-v0")
    space = env.observation_space
    buf = GoalCostReplayBuffer(50, space, env.action_space, device="cpu",
                               compute_terminated=env.unwrapped.compute_terminated,
                               achieved_goal_is_observation=True, seed=0)
    assert buf.observations["achieved_goal"] is buf.observations["observation"]
    obs, info = env.reset(seed=0)
    for t in range(30):
        nxt, _, term, trunc, info2 = env.step(env.action_space.sample())
        done = term or trunc or t % 10 == 9
        buf.add({k: v[None] for k, v in obs.items()}, {k: v[None] for k, v in nxt.items()},
                np.zeros((1, 2), np.float32), np.array([-1.0]), np.array([done]), [info2])
        obs = env.reset()[0] if done else nxt
    path = str(tmp_path / "replay.npz")
    buf.save_arrays(path)
    other = GoalCostReplayBuffer(50, space, env.action_space, device="cpu",
                                 compute_terminated=env.unwrapped.compute_terminated,
                                 achieved_goal_is_observation=True, seed=0)
    other.load_arrays(path)
    assert other.pos == buf.pos and other.n_complete_transitions() == buf.n_complete_transitions() == 30
    np.testing.assert_array_equal(other.observations["observation"][:30], buf.observations["observation"][:30])
    np.testing.assert_array_equal(other.costs[:30], buf.costs[:30])
    np.testing.assert_array_equal(other.positions[:30], buf.positions[:30])
    b1, b2 = buf.sample(8), other.sample(8)
    assert th.equal(b1.observations["observation"], b2.observations["observation"])
    small = GoalCostReplayBuffer(40, space, env.action_space, device="cpu",
                                 compute_terminated=env.unwrapped.compute_terminated)
    with pytest.raises(ValueError, match="holds a buffer of 50"):
        small.load_arrays(path)
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="bad.npz: it is not a replay-buffer file"):
        other.load_arrays(str(tmp_path / "bad.npz"))
