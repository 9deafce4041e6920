"""The ``mapf`` command on small MovingAI files written by the test (runs without the benchmark)."""
import json

import pytest

import agents.search.mapf.context as context_module
from baselines.cli import main


def write_instance(tmp_path, rows, agents):
    """A MovingAI ``.map`` of ``rows`` and a ``.scen`` of ``agents`` ``((sr, sc), (gr, gc))``."""
    m = tmp_path / "tiny.map"
    m.write_text(f"type octile\nheight {len(rows)}\nwidth {len(rows[0])}\nmap\n" + "\n".join(rows) + "\n")
    s = tmp_path / "tiny.scen"
    lines = ["version 1"]
    for (sr, sc), (gr, gc) in agents:
        # MovingAI scenarios give x (column) before y (row)
        lines.append(f"0\ttiny.map\t{len(rows[0])}\t{len(rows)}\t{sc}\t{sr}\t{gc}\t{gr}\t0")
    s.write_text("\n".join(lines) + "\n")
    return m, s


@pytest.fixture
def open_grid(tmp_path):
    # agents crossing a 6 x 6 open grid (one blocked cell)
    agents = [((r, 0), (5 - r, 5)) for r in range(6)] + [((0, c), (5, 5 - c)) for c in range(1, 5)]
    return write_instance(tmp_path, ["......", "......", "..@...", "......", "......", "......"], agents)


def test_memory_limit_flag_reaches_the_solver(open_grid, monkeypatch, capsys):
    m, s = open_grid
    # a process that seems to grow by 1 GiB every time the guard looks at it
    reads = iter(range(10**9))
    monkeypatch.setattr(context_module, "_rss_bytes", lambda: next(reads) * (1 << 30))
    rc = main(["mapf", str(m), str(s), "--agents", "10", "--memory-limit", "2", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert rc == 1 and report["status"] == "timeout" and "memory limit" in report["message"]
    # 0 turns the guard off: the same seemingly growing process now gets its answer
    rc = main(["mapf", str(m), str(s), "--agents", "10", "--memory-limit", "0", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert rc == 0 and report["status"] == "optimal" and report["valid"] is True


def test_negative_memory_limit_is_refused(open_grid, capsys):
    m, s = open_grid
    rc = main(["mapf", str(m), str(s), "--agents", "2", "--memory-limit", "-5"])
    assert rc != 0 and "memory_limit_mb must be > 0" in capsys.readouterr().err


def test_a_scenario_that_cannot_be_read_names_its_file_and_line(tmp_path):
    from agents.search.mapf import load_scen

    scen = tmp_path / "broken.scen"
    scen.write_text("version 1\n0\tx.map\t8\t8\t1\t1\t5\t5\t5.6\n0\tx.map\t8\t8\tone\t1\t5\t5\t5.6\n")
    with pytest.raises(ValueError, match=r"broken\.scen:3: cannot read"):
        load_scen(scen)


def test_a_scenario_of_another_map_is_refused(tmp_path, capsys):
    from agents.search.mapf import load_instance

    rows = ["....", "....", "...."]
    m, s = write_instance(tmp_path, rows, [((0, 0), (2, 3))])
    assert load_instance(m, s).starts == [0]
    s.write_text("version 1\n0\tmaps/other.map\t4\t3\t0\t0\t3\t2\t3.8\n")
    with pytest.raises(ValueError, match="agent 0 belongs to map 'maps/other.map', not 'tiny.map'"):
        load_instance(m, s)
    s.write_text("version 1\n0\tmaps/tiny.map\t8\t8\t0\t0\t3\t2\t3.8\n")  # folders aside, the size differs
    with pytest.raises(ValueError, match="for a 8x8 map .* tiny.map is 4x3"):
        load_instance(m, s)
    assert main(["mapf", str(m), str(s), "--agents", "1"]) == 2
    err = capsys.readouterr().err
    assert "tiny.map is 4x3" in err and "Traceback" not in err


def test_a_closed_pipe_ends_the_command_quietly():
    import subprocess
    import sys

    # the reader is gone before the command writes (like `safe-mapf envs --json | head -c 0`)
    code = ("import sys, time; from baselines.cli import main; time.sleep(1.0); "
            "sys.exit(main(['envs', '--json']))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 1  # the BrokenPipeError branch
    assert "Traceback" not in err and "BrokenPipeError" not in err
