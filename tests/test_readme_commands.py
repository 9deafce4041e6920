"""The shell commands of the README and of the documentation pages (``docs/**/*.md``): every one
parses as written, and the cheap ones run.

Commands are collected from the ``bash`` blocks (continuation lines joined, the apartment loop
run for one apartment) and from inline code that starts with ``safe-mapf`` or
``python examples/``. ``safe-mapf`` commands are parsed by the CLI's parser; example scripts
are run up to their ``parse_args`` (which must accept the arguments), then stopped before any
work. Usage patterns with placeholders (``...``, ``[--ray]``, ``F,K,S``) are skipped.
"""
import argparse
import re
import runpy
import shlex
import sys
from pathlib import Path

import pytest

from baselines.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]

#: Scripts without arguments: nothing to parse, and they do their (long) work at once.
NO_ARGUMENTS = {"examples/demo.py", "examples/plan_and_execute.py"}
#: Inline mentions of a command's name rather than commands.
NAMES = {"safe-mapf", "safe-mapf mapf"}
#: Commands cheap enough to run in full (they read shipped result files).
CHEAP = {
    "safe-mapf envs",
    "python examples/centerdot_table.py examples/table1/centerdot_paper examples/table1/centerdot_strict",
    "python examples/visual_table.py examples/table2/apt0 examples/table2/apt1 examples/table2/apt2 "
    "examples/table2/apt3",
    "python examples/visual_table.py --protocol paper examples/table2/paper/apt0 examples/table2/paper/apt1 "
    "examples/table2/paper/apt2 examples/table2/paper/apt3",
}


def page_commands(text: str):
    """The commands of one Markdown text (see the module docstring)."""
    cmds = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        joined = block.replace("\\\n", " ")
        for line in joined.splitlines():
            line = line.split("#", 1)[0].strip()
            line = line.replace("SafeApartment$a-v0", "SafeApartment0-v0").replace("apt$a", "apt0")
            if line.startswith(("safe-mapf ", "python examples/")):
                cmds.append(" ".join(line.split()))
    for code in re.findall(r"`((?:OMP_NUM_THREADS=1 )?(?:safe-mapf|python examples/)[^`]*)`", text):
        cmds.append(" ".join(code.replace("OMP_NUM_THREADS=1 ", "").split()))
    return {c for c in cmds if not re.search(r"\.\.\.|\[|F,K,S|\|", c)} - NAMES


PAGE_COMMANDS = {page.relative_to(ROOT).as_posix(): page_commands(page.read_text()) for page in PAGES}
COMMANDS = sorted(set().union(*PAGE_COMMANDS.values()))


class _Parsed(Exception):
    """Raised right after a script's parse_args accepted its arguments."""


def test_the_readme_and_the_docs_have_commands_of_both_kinds():
    assert any(c.startswith("safe-mapf evaluate") for c in PAGE_COMMANDS["README.md"])
    assert any(c.startswith("python examples/centerdot_table.py") for c in COMMANDS)
    assert any(c.startswith("python examples/bench_cbs.py") for c in PAGE_COMMANDS["docs/mapf.md"])
    assert CHEAP <= set(COMMANDS)


def test_commands_are_read_from_bash_blocks_and_inline_code():
    text = ("Run `safe-mapf envs` or:\n\n```bash\nsafe-mapf evaluate --agents 1 \\\n    --problems 2  # two\n"
            "safe-mapf train ... --resume\n```\n")
    assert page_commands(text) == {"safe-mapf envs", "safe-mapf evaluate --agents 1 --problems 2"}


@pytest.mark.parametrize("command", COMMANDS)
def test_a_readme_command_parses_as_written(command, monkeypatch):
    argv = shlex.split(command)
    if argv[0] == "safe-mapf":
        if "--help" in argv:
            with pytest.raises(SystemExit) as exit_:
                build_parser().parse_args(argv[1:])
            assert exit_.value.code == 0
        else:
            build_parser().parse_args(argv[1:])  # SystemExit(2) on a flag that does not exist
        return
    script = argv[1]
    assert (ROOT / script).is_file(), f"{script} does not exist"
    if script in NO_ARGUMENTS:
        assert len(argv) == 2, f"{script} takes no arguments"
        return
    real = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):
        real(self, args, namespace)
        raise _Parsed

    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_then_stop)
    monkeypatch.setattr(sys, "argv", argv[1:])
    with pytest.raises(_Parsed):
        runpy.run_path(str(ROOT / script), run_name="__main__")


@pytest.mark.parametrize("command", sorted(CHEAP))
def test_the_cheap_readme_commands_run(command, monkeypatch, capsys):
    argv = shlex.split(command)
    monkeypatch.chdir(ROOT)
    if argv[0] == "safe-mapf":
        assert main(argv[1:]) == 0
    else:
        monkeypatch.setattr(sys, "argv", argv[1:])
        runpy.run_path(str(ROOT / argv[1]), run_name="__main__")
    assert capsys.readouterr().out.strip()


def test_figure_scripts_write_to_their_folder_unless_asked_to_refresh_the_readme(tmp_path, monkeypatch):
    from baselines.output import FIGURES_OUT, add_figure_output_arguments, figure_output_dir

    parser = argparse.ArgumentParser()
    add_figure_output_arguments(parser)
    assert parser.parse_args([]).out == FIGURES_OUT
    readme = tmp_path / "readme"
    assert figure_output_dir(parser.parse_args(["--out", str(tmp_path / "f")]), readme) == tmp_path / "f"
    assert figure_output_dir(parser.parse_args(["--refresh-readme"]), readme) == readme and readme.is_dir()
    tracked = sorted((ROOT / "examples" / "figures" / "maps").glob("*.png"))
    before = [p.stat().st_mtime_ns for p in tracked]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["make_map_figures.py"])
    runpy.run_path(str(ROOT / "examples" / "make_map_figures.py"), run_name="__main__")
    assert sorted(p.name for p in (tmp_path / "figures_out" / "maps").glob("*.png")) == [p.name for p in tracked]
    assert [p.stat().st_mtime_ns for p in tracked] == before
