"""Two evaluations compared run by run (baselines.compare, examples/compare_runs.py)."""
import csv

import numpy as np
import pytest

from baselines.compare import comparison_table, merge, pair_methods, pair_runs, paired_interval

FIELDS = ["method", "agents", "difficulty", "problem", "success", "cost_max", "steps"]


def rows(outcomes, method="ours", agents=5, difficulty="hard"):
    """runs.csv rows as baselines.output.read_rows reads them: one per (success, cost, steps), problems 0, 1, ..."""
    return [{"method": method, "agents": agents, "difficulty": difficulty, "problem": i, "success": ok,
             "cost_max": c, "steps": s} for i, (ok, c, s) in enumerate(outcomes)]


def test_runs_are_paired_by_problem_into_gains_losses_and_cost_changes():
    before = rows([(True, 10.0, 50), (True, 20.0, 60), (False, 0.0, 300), (True, 5.0, 40)])
    after = rows([(True, 10.0, 50), (False, 0.0, 300), (True, 30.0, 90), (True, 8.0, 45)])
    (c,) = pair_runs(before, after)
    assert c.cell == ("ours", 5, "hard") and c.runs == 4
    assert (c.arrived_before, c.arrived_after, c.lost, c.gained, c.unchanged) == (3, 3, [1], [2], 1)
    assert c.cost_before == [10.0, 5.0] and c.cost_after == [10.0, 8.0]  # the runs that arrived both ways
    table = comparison_table([c])
    assert "| ours, 5 agents, hard | 4 | 3 -> 3 | 1 (1) | 1 (2) | 1 | 7.50 -> 9.00 | +1.50 [" in table


def test_only_problems_in_both_count_and_mistakes_are_refused():
    before = rows([(True, 1.0, 9)] * 3)
    (c,) = pair_runs(before, rows([(True, 1.0, 9)] * 2))
    assert c.runs == 2
    with pytest.raises(ValueError, match="share no run"):
        pair_runs(before, rows([(True, 1.0, 9)], agents=10))
    with pytest.raises(ValueError, match="problem 0 twice"):
        pair_runs(before + before[:1], before)


def test_the_paired_interval_brackets_the_mean_and_is_empty_for_equal_runs():
    rng = np.random.default_rng(1)
    a = rng.normal(50, 10, size=200)
    mean, lo, hi = paired_interval(a, a + 2 + rng.normal(0, 1, size=200))
    assert lo < mean < hi and 1.5 < lo and hi < 2.5
    assert paired_interval(a, a) == (0.0, 0.0, 0.0)
    assert all(np.isnan(paired_interval([], [])))


def test_two_methods_of_one_evaluation_are_paired_problem_by_problem():
    runs = (rows([(True, 10.0, 50), (True, 20.0, 60), (False, 0.0, 300)], method="sorb")
            + rows([(True, 7.0, 40), (False, 0.0, 300), (True, 9.0, 45)])
            + rows([(True, 1.0, 9)], method="sorb", agents=10) + rows([(True, 4.0, 9)], agents=10))
    five, ten = pair_methods(runs, "sorb", "ours")
    assert five.cell == ("ours - sorb", 5, "hard") and ten.cell == ("ours - sorb", 10, "hard")
    # only sorb arrived at problem 1, only ours at problem 2; both at problem 0: ours 3 cheaper
    assert (five.lost, five.gained, five.cost_before, five.cost_after) == ([1], [2], [10.0], [7.0])
    assert paired_interval(five.cost_before, five.cost_after)[0] == -3.0
    assert (ten.cost_before, ten.cost_after) == ([1.0], [4.0])
    with pytest.raises(ValueError, match="no run of 'marl'"):
        pair_methods(runs, "marl", "ours")
    with pytest.raises(ValueError, match="twice"):
        pair_methods(runs, "ours", "ours")


def test_cells_merge_into_a_total_row():
    one = pair_runs(rows([(True, 1.0, 9), (False, 0, 300)]), rows([(False, 0, 300), (True, 2.0, 9)]))
    two = pair_runs(rows([(True, 4.0, 9)], agents=10), rows([(True, 6.0, 9)], agents=10))
    total = merge(one + two, ("all", 0, ""))
    assert (total.runs, total.lost, total.gained, total.cost_before, total.cost_after) == (3, [0], [1], [4.0], [6.0])
    assert comparison_table(one + two).splitlines()[-1].startswith("| all | 3 | 2 -> 2 | 1 (0) | 1 (1) |")


def write(folder, table):
    folder.mkdir()
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(table)


def test_the_example_compares_folder_pairs_and_refuses_mismatched_folders(tmp_path, run_example):
    write(tmp_path / "b0", rows([(True, 3.0, 9), (True, 5.0, 9)]) + rows([(True, 1.0, 9)], method="sorb"))
    write(tmp_path / "a0", rows([(True, 3.0, 9), (False, 0, 300)]) + rows([(False, 0, 300)], method="sorb"))
    write(tmp_path / "b1", rows([(False, 0, 300)], agents=10))
    write(tmp_path / "a1", rows([(True, 7.0, 20)], agents=10))
    b0, b1, a0, a1 = (str(tmp_path / n) for n in ("b0", "b1", "a0", "a1"))
    code, out = run_example("compare_runs.py", "--before", b0, b1, "--after", a0, a1, "--methods", "ours")
    assert code == 0
    assert "| ours, 5 agents, hard | 2 | 2 -> 1 | 1 (1) | 0 | 1 | 3.00 -> 3.00 |" in out.out
    assert "sorb" not in out.out
    assert "## all folders" in out.out and "| all | 3 | 2 -> 2 | 1 (1) | 1 (0) |" in out.out
    code, out = run_example("compare_runs.py", "--before", b0, "--after", a0, a1)
    assert code == 2 and "1 folders before but 2 after" in out.err
    code, out = run_example("compare_runs.py", "--before", str(tmp_path / "b0"), "--after", str(tmp_path / "a1"))
    assert "share no run" in str(code)
    code, out = run_example("compare_runs.py", "--before", str(tmp_path / "b0"), "--after", str(tmp_path / "nothing"))
    assert "does not exist" in str(code)
    # two methods within each folder: ours against sorb in b0 (problem 0 only: 3.0 against 1.0)
    code, out = run_example("compare_runs.py", "--between", "sorb", "ours", "--before", b0)
    assert code == 0 and "## " + b0 + ": ours - sorb" in out.out
    assert "| ours - sorb, 5 agents, hard | 1 | 1 -> 1 | 0 | 0 | 0 | 1.00 -> 3.00 | +2.00 [" in out.out
    code, out = run_example("compare_runs.py", "--between", "sorb", "ours", "--before", b0, "--after", a0)
    assert code == 2 and "give no --after" in out.err
    code, out = run_example("compare_runs.py", "--before", b0)
    assert code == 2 and "--after is required" in out.err
    code, out = run_example("compare_runs.py", "--between", "sorb", "marl", "--before", b0)
    assert "no run of 'marl'" in str(code)
