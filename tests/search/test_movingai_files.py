"""MovingAI ``.map`` / ``.scen`` files that break the format are refused with the file and line named."""
from pathlib import Path

import pytest

from agents.search.mapf import load_instance, load_map, load_scen
from agents.search.mapf.movingai import BLOCKED_CHARS, FREE_CHARS, MovingAIFormatError
from baselines.cli import main

DATA = Path(__file__).resolve().parents[2] / "examples" / "data" / "movingai"


def write_map(tmp_path, rows, height=None, width=None, name="grid.map"):
    path = tmp_path / name
    h = len(rows) if height is None else height
    w = (len(rows[0]) if rows else 0) if width is None else width
    path.write_text(f"type octile\nheight {h}\nwidth {w}\nmap\n" + "".join(r + "\n" for r in rows))
    return path


def write_scen(tmp_path, lines, name="grid.scen"):
    path = tmp_path / name
    path.write_text("version 1\n" + "".join(line + "\n" for line in lines))
    return path


def test_every_shipped_map_and_scenario_loads():
    maps = sorted((DATA / "maps").glob("*.map")) + sorted((DATA / "tiny").glob("*.map"))
    scens = sorted((DATA / "scens").glob("*.scen")) + sorted((DATA / "tiny").glob("*.scen"))
    assert len(maps) >= 6 and len(scens) >= 6
    for m in maps:
        grid = load_map(m)
        assert grid.free.shape == (grid.height, grid.width) and grid.free.any()
    for s in scens:
        assert load_scen(s)


def test_every_known_character_is_read_as_free_or_blocked(tmp_path):
    assert FREE_CHARS == set(".GS") and BLOCKED_CHARS == set("@OTW")
    grid = load_map(write_map(tmp_path, [".GS@", "OTW."]))
    assert grid.free.tolist() == [[True, True, True, False], [False, False, False, True]]
    # Windows line ends and trailing blanks of a row are not part of the grid
    path = tmp_path / "crlf.map"
    path.write_bytes(b"type octile\r\nheight 2\r\nwidth 2\r\nmap\r\n.@ \r\n..\r\n\r\n")
    assert load_map(path).free.tolist() == [[True, False], [True, True]]


@pytest.mark.parametrize("char", ["X", "#", "1", " "])
def test_an_unknown_map_character_is_refused_with_file_line_and_character(tmp_path, char):
    path = write_map(tmp_path, ["....", f"..{char}."], width=4)
    with pytest.raises(MovingAIFormatError, match=rf"grid\.map:6: unknown map character {char!r} in column 3"):
        load_map(path)


def test_a_binary_file_is_refused_with_its_name(tmp_path):
    path = tmp_path / "image.map"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    with pytest.raises(MovingAIFormatError, match=r"image\.map: not a text file"):
        load_map(path)
    scen = tmp_path / "image.scen"
    scen.write_bytes(b"version 1\n\x00\x01\x02")
    with pytest.raises(MovingAIFormatError, match=r"image\.scen: not a text file"):
        load_scen(scen)


@pytest.mark.parametrize("height, width", [(0, 0), (0, 4), (3, 0), (-1, 4)])
def test_an_empty_map_is_refused_with_its_name(tmp_path, height, width):
    path = write_map(tmp_path, [], height=height, width=width)
    with pytest.raises(MovingAIFormatError, match=rf"grid\.map: the header gives a {height} x {width} map"):
        load_map(path)


def test_rows_of_another_width_are_refused_with_their_line(tmp_path):
    with pytest.raises(MovingAIFormatError, match=r"grid\.map:6: row of 3 characters, the header gives width 4"):
        load_map(write_map(tmp_path, ["....", "...", "...."], width=4))
    with pytest.raises(MovingAIFormatError, match=r"grid\.map:7: row of 5 characters, the header gives width 4"):
        load_map(write_map(tmp_path, ["....", "....", "....."], width=4))


def test_a_grid_of_another_height_is_refused(tmp_path):
    with pytest.raises(MovingAIFormatError, match=r"grid\.map: the header gives height 4, the grid has 3 rows"):
        load_map(write_map(tmp_path, ["...."] * 3, height=4))
    with pytest.raises(MovingAIFormatError, match=r"grid\.map:7: the header gives height 2, the grid goes on"):
        load_map(write_map(tmp_path, ["...."] * 3, height=2))


def test_bad_scenario_lines_are_refused_with_their_line(tmp_path):
    with pytest.raises(MovingAIFormatError, match=r"grid\.scen:3: expected 9 columns, got 5"):
        load_scen(write_scen(tmp_path, ["0\tgrid.map\t4\t2\t0\t0\t3\t1\t3", "0\tgrid.map\t4\t2\t0"]))
    with pytest.raises(MovingAIFormatError, match=r"grid\.scen:2: cannot read the agent's bucket, cells or length"):
        load_scen(write_scen(tmp_path, ["0\tgrid.map\t4\t2\t0\t0\t3\t1\tfar"]))
    with pytest.raises(MovingAIFormatError, match=r"grid\.scen:2: negative cell coordinate"):
        load_scen(write_scen(tmp_path, ["0\tgrid.map\t4\t2\t-1\t0\t3\t1\t3"]))
    with pytest.raises(MovingAIFormatError, match=r"grid\.scen: no agent lines"):
        load_scen(write_scen(tmp_path, []))


def test_a_blocked_or_outside_cell_names_the_scenario_line(tmp_path):
    m = write_map(tmp_path, ["....", ".@.."])
    ok = "0\tgrid.map\t4\t2\t0\t0\t3\t1\t3"
    s = write_scen(tmp_path, [ok, "0\tgrid.map\t4\t2\t1\t1\t3\t1\t2"])  # start x=1, y=1 is the '@'
    with pytest.raises(ValueError, match=r"grid\.scen:3: agent 1 start \(row=1, col=1\) is not a free cell"):
        load_instance(m, s)
    s = write_scen(tmp_path, [ok, "", "0\tgrid.map\t4\t2\t0\t0\t9\t1\t9"])
    with pytest.raises(ValueError, match=r"grid\.scen:4: agent 1 goal \(row=1, col=9\) is not a free cell"):
        load_instance(m, s)


@pytest.mark.parametrize("rows, width, expected", [
    (["....", ".?.."], None, "unknown map character '?'"),
    ([], 0, "the header gives a 0 x 0 map"),
    (["....", "..."], 4, "row of 3 characters"),
])
def test_the_command_prints_the_refusal_and_exits_with_2(tmp_path, capsys, rows, width, expected):
    m = write_map(tmp_path, rows, width=width)
    s = write_scen(tmp_path, ["0\tgrid.map\t4\t2\t0\t0\t3\t1\t3"])
    assert main(["mapf", str(m), str(s), "--agents", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("safe-mapf mapf: error: ") and str(m) in err and expected in err
    assert "Traceback" not in err


def test_the_command_names_a_binary_map(tmp_path, capsys):
    m = tmp_path / "noise.map"
    m.write_bytes(bytes(range(256)))
    s = write_scen(tmp_path, ["0\tnoise.map\t4\t2\t0\t0\t3\t1\t3"])
    assert main(["mapf", str(m), str(s), "--agents", "1"]) == 2
    err = capsys.readouterr().err
    assert f"safe-mapf mapf: error: {m}: not a text file" in err and "codec" not in err


def test_a_good_instance_still_solves(tmp_path, capsys):
    m = write_map(tmp_path, [".G.S", ".@T.", "...."])  # a ring round the two blocked cells
    s = write_scen(tmp_path, ["0\tgrid.map\t4\t3\t0\t0\t3\t1\t4", "0\tgrid.map\t4\t3\t3\t0\t0\t1\t4"])
    assert main(["mapf", str(m), str(s), "--agents", "2"]) == 0
    assert "optimal" in capsys.readouterr().out
