"""The fast commands of ``safe-mapf`` (listing, help, refused arguments, grid MAPF) do not import torch.

Each command runs in a fresh interpreter through ``baselines.cli.main``; a small wrapper then
reports whether ``torch`` is in ``sys.modules``.
"""
import json
import subprocess
import sys

import pytest

WRAPPER = """
import json, sys
from baselines.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:  # --help and argparse's refusals exit from parse_args
    code = exc.code
sys.stdout.flush()
print("\\nIMPORTS " + json.dumps({"code": code, "torch": "torch" in sys.modules}))
"""


def run_cli(args, cwd):
    proc = subprocess.run([sys.executable, "-c", WRAPPER, *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)
    line = [x for x in proc.stdout.splitlines() if x.startswith("IMPORTS ")]
    assert line, proc.stdout + proc.stderr
    return json.loads(line[-1][len("IMPORTS "):]), proc


@pytest.fixture
def tiny_instance(tmp_path):
    (tmp_path / "tiny.map").write_text("type octile\nheight 2\nwidth 3\nmap\n...\n.@.\n")
    (tmp_path / "tiny.scen").write_text("version 1\n0\ttiny.map\t3\t2\t0\t0\t2\t1\t3\n")
    return tmp_path


@pytest.mark.parametrize("args, code", [
    (["envs"], 0),
    (["--help"], 0),
    (["evaluate", "--agents", "0"], 2),
    (["mapf", "tiny.map", "tiny.scen", "--agents", "1", "--json"], 0),
], ids=["envs", "help", "refused-argument", "mapf"])
def test_a_fast_command_does_not_import_torch(args, code, tiny_instance):
    report, proc = run_cli(args, tiny_instance)
    assert report["code"] == code, proc.stdout + proc.stderr
    if args[0] == "mapf":
        assert json.loads(proc.stdout.splitlines()[0])["status"] == "optimal"
    assert report["torch"] is False, f"safe-mapf {' '.join(args)} imported torch"
