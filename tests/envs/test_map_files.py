"""Maps of one's own: MovingAI files, occupancy images and arrays become envs under ids of their own."""
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import safe_mapf_envs
from baselines.cli import main
from safe_mapf_envs import GridMap
from safe_mapf_envs.maps import MapFileError, map_name_from_path
from safe_mapf_envs.maps.files import MovingAIFormatError
from safe_mapf_envs.registration import env_spec, map_specs, register_spec

ROOT = Path(__file__).resolve().parents[2]
MOVINGAI_MAPS = sorted((ROOT / "examples" / "data" / "movingai" / "maps").glob("*.map"))
LARGE_MAP = ROOT / "examples" / "data" / "maps" / "scatter-64-64.map"


def write_map(path: Path, rows, height=None, width=None) -> Path:
    h = len(rows) if height is None else height
    w = len(rows[0]) if width is None else width
    path.write_text("\n".join(["type octile", f"height {h}", f"width {w}", "map", *rows]) + "\n")
    return path


def test_the_benchmark_maps_are_shipped():
    assert len(MOVINGAI_MAPS) >= 6 and LARGE_MAP.exists()


@pytest.mark.parametrize("path", MOVINGAI_MAPS + [LARGE_MAP], ids=lambda p: p.stem)
def test_every_movingai_map_builds_envs_that_pass_the_gymnasium_and_pettingzoo_checks(path):
    layout = GridMap.from_movingai(path)
    blocked = np.array([[ch not in ".GS" for ch in row] for row in path.read_text().splitlines()[4:]])
    assert layout.shape == blocked.shape
    assert layout.size == (3.0 * blocked.shape[1], 3.0 * blocked.shape[0])
    # every cell the file blocks stays blocked; free cells go only where they are cut off
    assert (layout.grid | ~blocked).all()
    env_id = safe_mapf_envs.register_map(layout)
    assert env_id == f"Safe{map_name_from_path(path)}-v0"
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.scenario.is_free(obs["observation"][None] * np.array(layout.size)).all()
    env.close()
    parallel_api_test(safe_mapf_envs.parallel_env(env_id, n_agents=6), num_cycles=20)


def test_a_map_file_is_read_cell_for_cell_and_closed_pockets_are_blocked(tmp_path):
    rows = ["....@..", "....@.@", "....@@.", "......."]
    # rows 0-1, columns 5-6 hold a pocket of three cells walled in by the map's edge and blocked cells
    path = write_map(tmp_path / "pocket.map", rows)
    kept = GridMap.from_movingai(path, largest_component=False, resize_factor=2.0)
    assert kept.rows == tuple(r.replace("@", "#") for r in rows)
    assert kept.size == (14.0, 8.0) and kept.cost_radius == 2.0 and kept.name == "Pocket"
    closed = GridMap.from_movingai(path, cost_radius=1.5)
    assert closed.grid[0, 5] and closed.grid[0, 6] and closed.grid[1, 5]
    assert (closed.grid != kept.grid).sum() == 3
    assert closed.cost_radius == 1.5


def test_images_and_arrays_give_the_same_map(tmp_path):
    blocked = np.zeros((6, 9), dtype=bool)
    blocked[2:4, 3:6] = True
    img = np.where(blocked, 0, 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "block.png"), img)
    np.save(tmp_path / "block.npy", blocked)
    from_png = GridMap.from_image(tmp_path / "block.png")
    from_npy = GridMap.from_file(tmp_path / "block.npy")
    from_ints = GridMap.from_array(blocked.astype(np.int64), "Block")
    assert from_png.rows == from_npy.rows == from_ints.rows
    assert (from_png.grid == blocked).all()
    grey = np.where(blocked, 100, 200).astype(np.uint8)  # a light threshold reads the grey block as free
    cv2.imwrite(str(tmp_path / "grey.png"), grey)
    assert not GridMap.from_image(tmp_path / "grey.png", threshold=90).grid.any()
    assert (GridMap.from_file(tmp_path / "grey.png").grid == blocked).all()


@pytest.mark.parametrize("rows, height, width, message", [
    (["....", "...", "...."], None, 4, r"bad\.map:6: row of 3 characters, the header gives width 4"),
    (["....", "..x.", "...."], None, None, r"bad\.map:6: unknown map character 'x' in column 3"),
    (["....", "...."], 3, None, r"bad\.map: the header gives height 3, the grid has 2 rows"),
])
def test_a_broken_movingai_file_is_refused_naming_the_file_and_line(tmp_path, rows, height, width, message):
    path = write_map(tmp_path / "bad.map", rows, height, width)
    with pytest.raises(MovingAIFormatError, match=message):
        GridMap.from_file(path)


def test_files_that_are_no_maps_are_refused_naming_the_file(tmp_path):
    write_map(tmp_path / "walls.map", ["@@@", "@@@"])
    with pytest.raises(MapFileError, match=r"walls\.map: every cell is blocked"):
        GridMap.from_movingai(tmp_path / "walls.map")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(MapFileError, match=r"text\.png: not an image"):
        GridMap.from_file(tmp_path / "text.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(MapFileError, match=r"empty\.png: not an image"):
        GridMap.from_image(tmp_path / "empty.png")
    with pytest.raises(MapFileError, match=r"missing\.map: no such file"):
        GridMap.from_file(tmp_path / "missing.map")
    with pytest.raises(MapFileError, match=r"map\.txt: unknown map format '\.txt'"):
        GridMap.from_file(tmp_path / "map.txt")
    np.save(tmp_path / "objects.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(MapFileError, match=r"objects\.npy: not a NumPy \.npy array that can be read without pickle"):
        GridMap.from_file(tmp_path / "objects.npy")
    np.save(tmp_path / "twos.npy", np.array([[0, 1], [2, 0]]))
    with pytest.raises(MapFileError, match=r"twos\.npy: .*row 1, column 0 holds 2"):
        GridMap.from_file(tmp_path / "twos.npy")
    np.save(tmp_path / "line.npy", np.zeros(5, dtype=bool))
    with pytest.raises(MapFileError, match=r"line\.npy: an occupancy grid must be a non-empty 2D array"):
        GridMap.from_file(tmp_path / "line.npy")


def test_register_map_takes_the_settings_of_its_base_and_refuses_clashes():
    room = GridMap.from_array(np.zeros((5, 5), dtype=bool), "Clearing", resize_factor=4.0)
    assert safe_mapf_envs.register_map(room) == "SafeClearing-v0"
    assert safe_mapf_envs.register_map(room) == "SafeClearing-v0"  # the same map again: the same id
    spec = env_spec("SafeClearing-v0")
    assert spec.kwargs["layout"] is room and spec.obs_type == "vector" and spec in map_specs()
    register_spec(spec)  # what a Ray worker given map_specs() does
    visual = safe_mapf_envs.register_map(room, base="SafeCentralObstacleVisual-v0")
    assert visual == "SafeClearingVisual-v0" and env_spec(visual).obs_type == "panorama"
    other = GridMap.from_array(np.zeros((3, 3), dtype=bool), "Clearing")
    with pytest.raises(ValueError, match="already registered for another map"):
        safe_mapf_envs.register_map(other)
    with pytest.raises(ValueError, match="one of this package's own ids"):
        safe_mapf_envs.register_map(other, env_id="SafeCenterDot-v0")
    with pytest.raises(KeyError, match="unknown env id 'SafeNoSuchBase-v0'"):
        safe_mapf_envs.register_map(other, base="SafeNoSuchBase-v0")
    env = gym.make("SafeClearing-v0")
    assert env.unwrapped.scenario.layout == room
    assert env.spec.max_episode_steps == env_spec("SafeCentralObstacle-v0").max_episode_steps


def test_the_commands_take_map_files_and_refuse_bad_ones_before_any_work(tmp_path, capsys):
    write_map(tmp_path / "ragged.map", ["....", "..."], width=4)
    for argv in (["train", "--map", str(tmp_path / "ragged.map"), "--out", str(tmp_path / "t")],
                 ["evaluate", "--map", str(tmp_path / "ragged.map"), "--out", str(tmp_path / "e")]):
        assert main(argv) == 2
        assert "ragged.map:6: row of 3 characters, the header gives width 4" in capsys.readouterr().err
    assert not (tmp_path / "t").exists() and not (tmp_path / "e").exists()
    path = write_map(tmp_path / "hall.map", ["........", "...@@...", "........"])
    assert main(["evaluate", "--map", str(path), "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err
    assert "no pretrained unconstrained checkpoint for 'SafeHall-v0'" in err
