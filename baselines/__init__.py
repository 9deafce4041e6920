"""Compared methods, the evaluation harness, tables, figures and the ``safe-mapf`` command line."""
