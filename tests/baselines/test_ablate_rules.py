"""examples/ablate_rules.py: each rule on by default turned off alone, on the same problems."""
import csv

from agents.search.config import SearchConfig, preset
from baselines.methods import METHODS


def test_only_the_rules_the_preset_has_on_are_ablated():
    import importlib.util

    spec = importlib.util.spec_from_file_location("ablate_rules", "examples/ablate_rules.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ours = METHODS["ours"]
    vector = dict(mod.variants(ours, ours.config(SearchConfig()), ["hold", "retreat", "safety_radius", "safety"]))
    assert sorted(vector) == ["safety", "safety_radius"]  # the vector preset keeps the clock and never retreats
    assert vector["safety_radius"].option("safety_radius") is None and vector["safety"].safety is False
    assert vector["safety"].name == "ours without safety" and vector["safety"].c_max == ours.c_max
    panorama = dict(mod.variants(ours, ours.config(preset("panorama")), ["hold", "retreat", "skip_after"]))
    assert panorama["hold"].option("hold") == "waits" and panorama["skip_after"].option("skip_after") == 2


def test_the_ablation_runs_the_defaults_and_each_rule_off_on_the_same_problems(run_example, tmp_path):
    code, out = run_example("ablate_rules.py", "--env", "SafeCentralObstacle-v0", "--agents", "2", "--problems", "1",
                            "--nodes", "150", "--rules", "safety", "hold", "--no-progress", "--out", str(tmp_path))
    assert code == 0
    rows = list(csv.DictReader((tmp_path / "runs.csv").open()))
    assert [r["method"] for r in rows] == ["ours", "ours without safety"] and rows[0]["problem"] == rows[1]["problem"]
    table = (tmp_path / "ablation.md").read_text()
    assert "| safety | the safety layer keeps agents from touching | 1 |" in table
    assert "off in this preset already: hold" in table and table in out.out
