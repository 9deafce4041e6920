"""Graph files record where they were made and are checked whole on loading: corrupt, foreign,
NaN or out-of-map files are refused naming the file; bad planner options name the valid ones."""
import copy

import numpy as np
import pytest
from gymnasium import spaces

from agents.search import SearchPolicy, WaypointGraph
from agents.search.config import UnknownOptionError
from agents.search.execution.repair import EdgeMemory

ENV = "SafeCentralObstacle-v0"
BOX = spaces.Box(0.0, 1.0, (2,), np.float32)
OBS_SPACE = spaces.Dict({"observation": BOX, "achieved_goal": BOX, "desired_goal": BOX})


@pytest.fixture
def models(stand_in_models):
    """The stand-in critic, told its environment and observation space, and one of another map."""
    critic = copy.copy(stand_in_models["constrained"])
    critic.env_id, critic.observation_space = ENV, OBS_SPACE
    other = copy.copy(critic)
    other.env_id = "SafeCenterDot-v0"
    return critic, other


@pytest.fixture
def nodes():
    return np.random.default_rng(0).uniform(0.05, 0.95, (30, 2)).astype(np.float32)


def rewrite_npz(src, dst, **changes):
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    for k in [k for k, v in changes.items() if v is None]:
        del arrays[k]
    np.savez_compressed(dst, **arrays)
    return dst


def test_a_waypoint_graph_records_its_env_and_checks_it(nodes, models, tmp_path):
    critic, other = models
    g = WaypointGraph.from_matrices(np.full((30, 30), 1.0), d_max=2.0, observations=nodes)
    path = tmp_path / "g.npz"
    g.save(path, env_id=ENV)
    back = WaypointGraph.load(path, env_id=ENV, observation_space=OBS_SPACE, models=[critic])
    np.testing.assert_array_equal(back.observations, nodes)
    with pytest.raises(ValueError, match=rf"g.npz was made on '{ENV}'; the environment is of 'SafeCenterDot-v0'"):
        WaypointGraph.load(path, env_id="SafeCenterDot-v0")
    with pytest.raises(ValueError, match=rf"g.npz was made on '{ENV}'"):
        WaypointGraph.load(path, models=[other])
    wide = spaces.Box(0.0, 1.0, (3,), np.float32)
    with pytest.raises(ValueError, match=r"g.npz: its node observations have shape \(2,\), the environment takes"):
        WaypointGraph.load(path, observation_space=wide)
    # a file without the record (written before graphs recorded it) still loads
    old = rewrite_npz(path, tmp_path / "old.npz", env_id=None, observation_shape=None)
    assert WaypointGraph.load(old, env_id="SafeCenterDot-v0").observations.shape == (30, 2)


@pytest.mark.parametrize("bad, match", [(np.nan, "not finite"), (1.5, "outside the bounds")])
def test_nan_or_out_of_map_nodes_are_refused(nodes, models, tmp_path, bad, match):
    critic, _ = models
    g = WaypointGraph.from_matrices(np.full((30, 30), 1.0), d_max=2.0, observations=nodes)
    path = tmp_path / "g.npz"
    g.save(path, env_id=ENV)
    broken = nodes.copy()
    broken[4, 1] = bad
    rewrite_npz(path, path, observations=broken)
    with pytest.raises(ValueError, match=f"g.npz: 1 node observations .*{match}.*node 4"):
        WaypointGraph.load(path, observation_space=OBS_SPACE)
    policy_path = SearchPolicy.from_models(critic, critic, nodes, seed=0).save(tmp_path / "p")
    rewrite_npz(policy_path, policy_path, observations=broken)
    with pytest.raises(ValueError, match=f"p.npz: 1 node observations .*{match}"):
        SearchPolicy.load(policy_path, critic)


def test_truncated_or_flipped_graph_files_name_the_file(nodes, tmp_path, flip_byte):
    g = WaypointGraph.from_matrices(np.full((30, 30), 1.0), d_max=2.0, observations=nodes)
    path = tmp_path / "g.npz"
    g.save(path)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(ValueError, match="cut.npz: it is not a waypoint graph file .*truncated or corrupt"):
        WaypointGraph.load(cut)
    flipped = flip_byte(path, tmp_path / "flip.npz", "observations.npy")
    with pytest.raises(ValueError, match="flip.npz: it is not a waypoint graph file .*truncated or corrupt"):
        WaypointGraph.load(flipped)


def test_a_search_policy_file_records_its_env_and_is_checked_whole(nodes, models, tmp_path, flip_byte):
    critic, other = models
    policy = SearchPolicy.from_models(critic, critic, nodes, seed=0)
    path = policy.save(tmp_path / "p")
    with np.load(path) as z:
        assert str(z["env_id"]) == ENV and tuple(z["observation_shape"]) == (2,)
    back = SearchPolicy.load(path, critic)
    np.testing.assert_array_equal(back.planner.D, policy.planner.D)
    with pytest.raises(ValueError, match=rf"p.npz was made on '{ENV}'.*'SafeCenterDot-v0'"):
        SearchPolicy.load(path, other)
    with pytest.raises(ValueError, match=rf"p.npz was made on '{ENV}'"):
        SearchPolicy.load(path, critic, other)
    old = rewrite_npz(path, tmp_path / "old.npz", env_id=None, observation_shape=None)
    assert SearchPolicy.load(old, other).planner.D.shape == (30, 30)  # files without the record still load
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(ValueError, match="cut.npz: it is not a saved SearchPolicy graph .*truncated or corrupt"):
        SearchPolicy.load(cut, critic)
    flipped = flip_byte(path, tmp_path / "flip.npz", "D.npy")
    with pytest.raises(ValueError, match="flip.npz.*truncated or corrupt"):
        SearchPolicy.load(flipped, critic)
    short = rewrite_npz(path, tmp_path / "short.npz", C=np.zeros((29, 29)))
    with pytest.raises(ValueError, match=r"short.npz: C must be a \(30, 30\) matrix"):
        SearchPolicy.load(short, critic)
    odd = rewrite_npz(path, tmp_path / "odd.npz", planner_config=np.array('{"graph": {"d_max": 2.0, "colour": 1}}'))
    with pytest.raises(ValueError, match=r"odd.npz: graph has unknown fields \['colour'\]; its fields are \[.*'d_max'"):
        SearchPolicy.load(odd, critic)
    bad = rewrite_npz(path, tmp_path / "bad.npz", planner_config=np.array('{"graph": {"d_max": -1}}'))
    with pytest.raises(ValueError, match=r"bad.npz: graph: d_max must be > 0"):
        SearchPolicy.load(bad, critic)
    code = rewrite_npz(path, tmp_path / "code.npz", planner_config=np.array('__import__("os")'))
    with pytest.raises(ValueError, match=r"code.npz: its planner_config are not JSON"):
        SearchPolicy.load(code, critic)
    # files that hold the planner's options by name load too, and are checked as well
    legacy = rewrite_npz(path, tmp_path / "legacy.npz", planner_config=None,
                         planner_options=np.array('{"d_max": 3.0, "solver": "lns"}'))
    loaded = SearchPolicy.load(legacy, critic)
    assert loaded.planner.graph.d_max == 3.0 and loaded.planner.solver_config.name == "lns"
    odd = rewrite_npz(path, tmp_path / "odd.npz", planner_config=None,
                      planner_options=np.array('{"d_max": 2.0, "colour": 1}'))
    with pytest.raises(ValueError, match=r"odd.npz: its planner options \['colour'\] .*valid: \[.*'d_max'"):
        SearchPolicy.load(odd, critic)


def test_unknown_planner_options_are_a_value_error_listing_the_valid_ones(nodes, models, tmp_path):
    critic, _ = models
    with pytest.raises(ValueError, match=r"unknown options \['cmax'\]; the options are \[.*'c_max'.*'hold'"):
        SearchPolicy.from_models(critic, critic, nodes, seed=0, cmax=0.5)
    path = SearchPolicy.from_models(critic, critic, nodes, seed=0).save(tmp_path / "p")
    with pytest.raises(UnknownOptionError, match=r"unknown options \['colour'\]"):
        SearchPolicy.load(path, critic, colour="red")


def test_an_edge_memory_file_is_read_whole(tmp_path):
    m = EdgeMemory(10)
    m.record_failure(1, 2)
    m.save(tmp_path / "m.npz")
    assert EdgeMemory.load(tmp_path / "m.npz").failures == m.failures
    cut = tmp_path / "cut.npz"
    cut.write_bytes((tmp_path / "m.npz").read_bytes()[:-60])
    with pytest.raises(ValueError, match="cut.npz.*truncated or corrupt"):
        EdgeMemory.load(cut)
