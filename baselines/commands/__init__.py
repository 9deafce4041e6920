"""Subcommands of the ``safe-mapf`` command line, one module each (see :mod:`baselines.cli`)."""
