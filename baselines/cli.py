"""The ``safe-mapf`` command line.

Each subcommand lives in its own module under :mod:`baselines.commands` and exposes
``register(subparsers)``, which adds an ``argparse`` parser whose ``func`` default runs the
command and returns an exit code. Heavy imports happen inside the command functions, so
``safe-mapf --help`` stays fast.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Sequence

from .distributed import MissingExtraError


class DefaultsHelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Appends "(default: X)" to an option's help only where it says something: not for flags
    (``store_true``/``store_false``), not for a default of ``None`` and not where the help text
    already states the default in words. Every subcommand's ``--help`` uses it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.nargs == 0 or action.default is None or "default" in text:
            return text
        return super()._get_help_string(action) or text


def show_progress(disabled: bool = False) -> bool:
    """Whether a command draws a progress bar: not when ``disabled``, and only on a terminal
    (a bar redrawn with ``\\r`` would fill a log file or a pipe with hundreds of lines)."""
    return not disabled and sys.stderr.isatty()


def add_map_argument(parser: argparse.ArgumentParser, env_option: str = "--env") -> None:
    """``--map FILE``: a map of one's own in place of the env's layout (see :func:`env_for_map`)."""
    parser.add_argument("--map", dest="map_file", default=None, metavar="FILE",
                        help="a map of your own (MovingAI .map, occupancy image, .npy boolean array; one cell per "
                             "character or pixel, 3 world units per cell) in place of the map of " + env_option
                             + ", which gives the other settings; the env id becomes Safe<file stem>-v0")


def env_for_map(env_id: str, map_file: str | None) -> str:
    """``env_id``, or where ``map_file`` is given the id of that map registered with ``env_id``'s
    settings (:func:`safe_mapf_envs.register_map`); a bad file raises ``ValueError`` naming it."""
    if not map_file:
        return env_id
    import safe_mapf_envs
    from safe_mapf_envs.maps import GridMap

    return safe_mapf_envs.register_map(GridMap.from_file(map_file), base=env_id)


#: Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "baselines.commands.envs",
    "baselines.commands.bench_env",
    "baselines.commands.mapf",
    "baselines.commands.train",
    "baselines.commands.train_marl",
    "baselines.commands.evaluate",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="safe-mapf",
        description="Safe multi-agent navigation: environments, agents, planning and evaluation.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command whose module is not part of this build
            if exc.name == name:
                continue
            raise
        module.register(sub)
    for command in sub.choices.values():
        command.formatter_class = DefaultsHelpFormatter
    return parser


def resume_command(argv: Sequence[str]) -> str:
    """The command line that continues a run started with ``argv`` (the arguments after
    ``safe-mapf``): ``--overwrite`` left out, ``--resume`` added."""
    import shlex

    tokens = [t for t in argv if t != "--overwrite"]
    return shlex.join(["safe-mapf", *tokens, *([] if "--resume" in tokens else ["--resume"])])


#: the exit code of a command stopped by Ctrl-C (128 + SIGINT), as shells report it
INTERRUPTED = 130


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``safe-mapf`` console script.

    Refused input exits with code 2 and one line naming the problem. Ctrl-C exits with code 130
    and one line saying what was kept and, for commands that resume, the command that continues
    the run (a command sets ``args.interrupt_note``, a function that returns that line)."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.argv = argv
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        note = getattr(args, "interrupt_note", None)
        try:
            text = note() if callable(note) else "nothing was kept"
        except Exception:  # noqa: BLE001 (a note that cannot be made must not hide the interruption)
            text = "interrupted"
        print(f"\nsafe-mapf {args.command}: interrupted; {text}", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:  # the reader went away (e.g. `safe-mapf envs --json | head`): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that flushing stdout at exit does not fail again
        return 1
    except (ValueError, OSError, MissingExtraError) as exc:  # bad input, unreadable or unwritable files
        print(f"safe-mapf {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
