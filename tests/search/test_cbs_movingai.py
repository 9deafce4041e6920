"""MovingAI grids: loading, conversion, CBS on benchmark instances, and the ``mapf`` command."""
import json
from pathlib import Path

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc

from agents.search.mapf import grid_graph, load_instance, load_map, load_scen, solve_cbs, validate
from baselines.cli import main

# the benchmark files ship with the repository
DATA = Path(__file__).resolve().parents[2] / "examples" / "data" / "movingai"


def paths_for(name, scen, k):
    return DATA / "maps" / f"{name}.map", DATA / "scens" / f"{name}-{scen}.scen"


def test_load_map_and_scen():
    m, s = paths_for("random-32-32-10", "random-1", 5)
    grid = load_map(m)
    rows = m.read_text().splitlines()[4:]
    assert (grid.height, grid.width) == (32, 32)
    assert grid.free.sum() == sum(ch in ".GS" for r in rows for ch in r)
    agents = load_scen(s, 5)
    assert len(agents) == 5
    first = s.read_text().splitlines()[1].split("\t")
    # x is the column, y the row
    assert agents[0].start == (int(first[5]), int(first[4]))
    assert agents[0].goal == (int(first[7]), int(first[6]))
    with pytest.raises(ValueError, match="requested"):
        load_scen(s, 10_000)


def test_grid_graph_is_four_connected():
    grid = load_map(paths_for("room-32-32-4", "random-1", 1)[0])
    g, cells, index = grid_graph(grid)
    assert g.shape == (grid.free.sum(),) * 2
    assert (g != g.T).nnz == 0  # undirected
    src, dst = g.nonzero()
    steps = np.abs(cells[src] - cells[dst]).sum(axis=1)
    assert (steps == 1).all()
    assert (index[cells[:, 0], cells[:, 1]] == np.arange(len(cells))).all()


@pytest.mark.parametrize("name, scen, k, soc", [
    ("empty-8-8", "random-1", 8, 45),
    ("empty-8-8", "random-3", 14, 64),
    ("random-32-32-10", "random-1", 10, 232),
    # needs real search; 656 was cross-checked with vanilla CBS (17k expansions)
    ("random-32-32-10", "random-2", 30, 656),
])
def test_benchmark_instances_are_solved_optimally(name, scen, k, soc):
    inst = load_instance(*paths_for(name, scen, k), k)
    res = solve_cbs(inst.graph, inst.starts, inst.goals, grid_coords=inst.cells, time_limit=30)
    assert res.status == "optimal" and res.soc == soc
    assert validate(inst.graph, inst.starts, inst.goals, res.paths) == []
    rc = inst.to_rowcol(res.node_sequences())
    for agent, path in zip(inst.agents, rc):
        assert tuple(path[0]) == agent.start and tuple(path[-1]) == agent.goal
    if k <= 14:  # small enough for plain CBS: the same optimum
        plain = solve_cbs(inst.graph, inst.starts, inst.goals, vanilla=True, time_limit=30)
        assert plain.soc == soc


def test_cli_json_and_paths_out(tmp_path, capsys):
    m, s = paths_for("empty-8-8", "random-1", 10)
    out = tmp_path / "paths.json"
    rc = main(["mapf", str(m), str(s), "--agents", "10", "--json", "--paths-out", str(out)])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    for key in ("status", "soc", "makespan", "runtime_s", "work", "stats"):
        assert key in report
    assert report["solver_used"] == "cbs" and report["stats"]["hl_expanded"] >= 0 and report["work"] > 0
    assert report["status"] == "optimal" and report["valid"] is True
    paths = json.loads(out.read_text())
    agents = load_scen(s, 10)
    assert len(paths) == 10
    assert sum(len(p) - 1 for p in paths) == report["soc"]
    for agent, p in zip(agents, paths):
        assert tuple(p[0]) == agent.start and tuple(p[-1]) == agent.goal
        for (r0, c0), (r1, c1) in zip(p, p[1:]):
            assert abs(r0 - r1) + abs(c0 - c1) <= 1


def test_cli_summary_and_limits(capsys):
    m, s = paths_for("empty-8-8", "random-5", 24)
    rc = main(["mapf", str(m), str(s), "--agents", "24", "--time-limit", "0.05"])
    text = capsys.readouterr().out
    assert rc == 1 and "timeout" in text
    rc = main(["mapf", str(m), str(s), "--agents", "6", "--suboptimality", "1.5", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert rc == 0 and report["status"] in ("optimal", "suboptimal") and report["valid"]



def test_tiny_pocket_instance_loads_with_its_stated_optimum():
    # three agents in a corridor with one pocket (the README of the data folder: optimum 25),
    # checked with the independent brute-force solver
    inst = load_instance(DATA / "tiny" / "pocket.map", DATA / "tiny" / "pocket.scen")
    assert len(inst.agents) == 3 and inst.graph.shape == (6, 6)
    src, dst = inst.graph.nonzero()
    edges = {(int(u), int(v)): 1 for u, v in zip(src, dst)}
    assert brute_force_soc(6, edges, inst.starts, inst.goals) == 25
