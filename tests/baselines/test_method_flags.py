"""The flags of ``safe-mapf evaluate`` that change the compared methods: one table, applied by it."""
import math

import pytest

from agents.search.config import OPTIONS, SearchConfig
from baselines.cli import build_parser, main
from baselines.commands.evaluate import APPLIES, METHOD_FLAGS, apply_method_flags
from baselines.methods import METHODS, Method, get_methods


def test_every_row_sets_a_config_option_or_a_methods_own_field_on_named_methods():
    for row in METHOD_FLAGS:
        assert row.option in OPTIONS or row.option in ("fallback", "safety"), row.flag
        assert row.applies in APPLIES and row.flag.startswith("--")
    assert len({row.flag for row in METHOD_FLAGS}) == len(METHOD_FLAGS)


def test_the_table_changes_only_the_methods_each_flag_applies_to():
    args = build_parser().parse_args(["evaluate", "--c-max", "0.5", "--hold", "order", "--fallback", "--safety", "off",
                                      "--max-edges", "12", "--budget", "3"])
    methods = {m.name: m for m in apply_method_flags(get_methods(["sorb", "constrained_policy", "ours", "ours_budget"]),
                                                     args)}
    assert methods["ours"].c_max == 0.5 and methods["ours_budget"].c_max == 0.5 and methods["sorb"].c_max == math.inf
    assert methods["ours_budget"].budget == 3.0 and methods["ours"].budget is None
    assert methods["sorb"].option("hold") == "order" and methods["constrained_policy"].option("hold") is None
    assert methods["ours"].fallback == "unconstrained" and methods["sorb"].fallback is None
    assert not any(m.safety for m in methods.values())
    assert methods["sorb"].option("max_edges") == 12 and methods["constrained_policy"].option("max_edges") is None
    plain = apply_method_flags(get_methods(["ours"]), build_parser().parse_args(["evaluate"]))
    assert plain == [METHODS["ours"]]  # no flag given, no change


def test_a_method_is_a_name_and_a_change_to_the_config():
    ours = METHODS["ours"]
    assert ours.options == (("c_max", 0.25),)
    assert METHODS["sorb"].config(SearchConfig()) == SearchConfig()  # SoRB changes nothing
    config = ours.with_options(hold="order").config(SearchConfig())
    assert config.graph.c_max == 0.25 and config.controller.hold == "order"
    with pytest.raises(ValueError, match=r"unknown options \['cmax'\]"):
        Method("bad", "Bad", "constrained", True, (("cmax", 0.3),))


def test_the_flags_that_change_methods_are_refused_under_the_paper_protocol(tmp_path, capsys):
    for argv in (["--hold", "order"], ["--fallback"], ["--c-max", "0.3"], ["--safety", "off"]):
        code = main(["evaluate", "--protocol", "paper", *argv, "--out", str(tmp_path / "x")])
        err = capsys.readouterr().err
        assert code != 0 and f"{argv[0]} does not apply to --protocol paper" in err
