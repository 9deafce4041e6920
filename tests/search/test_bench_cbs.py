"""examples/bench_cbs.py: the same answers serially and on Ray."""
import importlib.util
import json
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "examples" / "bench_cbs.py"


def load_bench():
    spec = importlib.util.spec_from_file_location("bench_cbs", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_cbs"] = module
    spec.loader.exec_module(module)
    return module


def test_bench_cbs_on_ray_gives_the_serial_answers(tmp_path, capsys):
    ray = pytest.importorskip("ray")
    bench = load_bench()
    # a generous time limit: on a busy CPU the Ray tasks share the cores with other work
    argv = ["--maps", "empty-8-8", "--scens", "random-1", "even-1", "--sweep", "--step", "12", "--time-limit", "120"]
    assert bench.main([*argv, "--out", str(tmp_path / "serial.json")]) == 0
    try:
        assert bench.main([*argv, "--ray", "--out", str(tmp_path / "ray.json")]) == 0
    finally:
        ray.shutdown()
    out = capsys.readouterr().out
    assert "on Ray (local)" in out

    def answers(name):
        rows = json.loads((tmp_path / name).read_text())
        return [(r["scen"], r["agents"], r["status"], r["soc"], r["hl_expanded"]) for r in rows]

    serial = answers("serial.json")
    assert [(s, k) for s, k, *_ in serial] == [("random-1", 12), ("random-1", 24), ("even-1", 12), ("even-1", 24)]
    assert all(status == "optimal" for _, _, status, _, _ in serial)
    assert answers("ray.json") == serial  # same instances, same order, same optimal costs and search


def test_bench_cbs_tiny_only_solves_the_tight_ones_and_reports_the_infeasible_ones(tmp_path, capsys):
    bench = load_bench()
    assert bench.main(["--tiny", "--maps", "--time-limit", "30", "--out", str(tmp_path / "tiny.json")]) == 0
    rows = json.loads((tmp_path / "tiny.json").read_text())
    names = {r["map"] for r in rows}
    assert {"pocket", "parked", "infeasible-ring", "infeasible-star"} <= names
    assert all(r["scen"] == "tiny" for r in rows)  # no MovingAI map was run
    for r in rows:
        want = "infeasible" if r["map"].startswith("infeasible-") else "optimal"
        assert r["status"] == want and r["solved"], r
    assert next(r for r in rows if r["map"] == "pocket")["soc"] == 25
    assert f"{len(rows)}/{len(rows)} solved" in capsys.readouterr().out
    with pytest.raises(SystemExit):  # no maps and no tiny instances: nothing to run
        bench.main(["--maps"])
    assert "--maps needs map names" in capsys.readouterr().err
