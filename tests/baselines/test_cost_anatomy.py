"""Where the largest cost goes (baselines.cost_anatomy, examples/cost_anatomy.py)."""
import csv
from pathlib import Path

import numpy as np
import pytest

from agents.search.execution.stats import ACTIVITIES
from baselines.cost_anatomy import (
    cost_anatomy,
    cost_anatomy_figure,
    cost_anatomy_table,
    cost_split_field,
    parse_cost_split,
)


def test_the_row_keeps_the_costliest_agents_split_and_reads_it_back():
    split = np.zeros((3, len(ACTIVITIES)))
    split[0, ACTIVITIES.index("drive")] = 4.0
    split[1, ACTIVITIES.index("drive")] = 3.0
    split[1, ACTIVITIES.index("park")] = 2.5
    split[2, ACTIVITIES.index("yield")] = 1.0
    field = cost_split_field(split, split.sum(1))
    assert field == "drive=3.00;park=2.50"
    assert parse_cost_split(field) == {"drive": 3.0, "park": 2.5}
    assert cost_split_field(np.zeros((0, len(ACTIVITIES))), np.zeros(0)) == "" and parse_cost_split("") == {}
    with pytest.raises(ValueError, match="unknown name 'nap' in cost_split"):
        parse_cost_split("drive=1.0;nap=2.0")


def rows():
    return [
        {"method": "ours", "agents": 5, "difficulty": "hard", "success": True, "cost_split": "drive=6.00;order=2.00"},
        {"method": "ours", "agents": 5, "difficulty": "hard", "success": True, "cost_split": "drive=2.00;park=4.00"},
        {"method": "ours", "agents": 5, "difficulty": "hard", "success": False, "cost_split": "escape=90.00"},
        {"method": "ours", "agents": 5, "difficulty": "easy", "success": True, "cost_split": "drive=1.00"},
        {"method": "sorb", "agents": 5, "difficulty": "hard", "success": True, "cost_split": ""},
    ]


def test_the_anatomy_averages_the_successful_runs_per_cell(tmp_path):
    summary = cost_anatomy(rows())
    assert [(c["method"], c["difficulty"], c["runs"]) for c in summary] == [("ours", "easy", 1), ("ours", "hard", 2)]
    hard = summary[1]
    assert hard["cost"] == pytest.approx(7.0) and hard["drive"] == pytest.approx(4.0)
    assert hard["order"] == pytest.approx(1.0) and hard["park"] == pytest.approx(2.0) and hard["escape"] == 0
    table = cost_anatomy_table(summary)
    assert "| ours | Hard | 5 | 2 | 7.00 | 4.00 (57%) | 0 | 0 | 0 | 1.00 (14%) | 2.00 (29%) | 0 | 0 |" in table
    path = cost_anatomy_figure(summary, tmp_path / "cost.png")
    assert path.stat().st_size > 1000
    with pytest.raises(ValueError, match="no cell"):
        cost_anatomy_figure([], tmp_path / "none.png")


def test_the_example_prints_the_split_and_refuses_folders_without_it(tmp_path, run_example):
    fields = ["method", "agents", "difficulty", "problem", "success", "cost_max", "cost_split"]
    folder = tmp_path / "run"
    folder.mkdir()
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for i, r in enumerate(rows()):
            w.writerow({**r, "problem": i, "cost_max": 1.0})
    code, out = run_example("cost_anatomy.py", str(folder), "--methods", "ours", "--agents", "5",
                            "--figure", str(tmp_path / "c.png"))
    assert code == 0 and "| ours | Hard | 5 | 2 | 7.00 |" in out.out and (tmp_path / "c.png").exists()
    code, out = run_example("cost_anatomy.py", str(folder), "--methods", "ours", "--summary")  # easy 1.00, hard 7.00
    assert code == 0 and "| ours | All | 5 | 3 | 4.00 | 2.50 (62%) | 0 | 0 | 0 | 0.50 (12%) | 1.00 (25%) |" in out.out
    code, out = run_example("cost_anatomy.py", str(folder), "--methods", "sorb")
    assert "no successful run with a cost split" in str(code)
    old = tmp_path / "old"
    old.mkdir()
    (old / "runs.csv").write_text("method,agents,difficulty,problem,success\nours,5,hard,0,True\n")
    code, out = run_example("cost_anatomy.py", str(old))
    assert "no cost_split column" in str(code)
    code, out = run_example("cost_anatomy.py", str(tmp_path / "nothing"))
    assert "does not exist" in str(code)


def test_the_plan_dependencies_example_counts_what_routes_share(run_example):
    def rows_of(*extra):
        code, out = run_example("plan_dependencies.py", "--env", "SafeCentralObstacle-v0", "--agents", "4",
                                "--problems", "2", "--nodes", "150", "--seed", "1", *extra)
        assert code == 0
        return {line.split("|")[1].strip(): [float(x) for x in line.split("|")[2:5]]
                for line in out.out.splitlines() if line.startswith("| sorb") or line.startswith("| ours")}

    rows = rows_of()
    assert set(rows) == {"sorb", "ours"} and all(v[0] >= 0 and v[1] >= 0 and v[2] > 0 for v in rows.values())
    spread = rows_of("--spread", "near")  # other plans: the planner's spread_routes reaches the solver
    assert set(spread) == {"sorb", "ours"} and spread != rows
    for argv, message in ((["--agents", "1"], "at least 2"), (["--methods", "constrained_policy"], "only search"),
                          (["--c-max-from", str(Path("examples/table2/apt3/c_max.json")), "--agents", "3"],
                           "no c_max for 3 agents")):
        code, out = run_example("plan_dependencies.py", *argv)
        assert code == 2 and message in out.err
