"""Contact anatomy: each contact between agents gets one reason, kept in the row and summed per cell."""
import numpy as np
import pytest

import safe_mapf_envs
from baselines.contact_anatomy import (
    CONTACT_REASONS,
    contact_reason,
    contact_reasons_field,
    contact_summary,
    contact_table,
    parse_contact_reasons,
)
from baselines.methods import METHODS, execute


@pytest.mark.parametrize("parked, goals_close, activities, holding, reason", [
    ((False, True), True, ("escape", "drive"), (True, False), "parked"),  # tested first
    ((False, False), True, ("escape", "drive"), (True, False), "goals_close"),
    ((False, False), False, ("drive", "fallback"), (True, False), "off_plan"),
    ((False, False), False, ("drive", "yield"), (False, True), "into_holding"),
    ((False, False), False, ("drive", None), (False, False), "both_driving"),
])
def test_a_contact_gets_the_first_reason_that_holds(parked, goals_close, activities, holding, reason):
    assert contact_reason(parked, goals_close, activities, holding) == reason


def test_the_row_field_round_trips_in_the_order_of_the_reasons():
    text = contact_reasons_field({"both_driving": 3, "parked": 1, "off_plan": 0})
    assert text == "parked=1;both_driving=3"
    assert parse_contact_reasons(text) == {"parked": 1, "both_driving": 3}
    assert contact_reasons_field({}) == "" and parse_contact_reasons("") == {}
    with pytest.raises(ValueError, match="unknown name 'bumped' in contact_reasons"):
        parse_contact_reasons("bumped=2")
    with pytest.raises(ValueError, match="unknown contact reasons"):
        contact_reasons_field({"bumped": 2})


def test_the_summary_adds_up_cells_and_leaves_out_runs_that_did_not_record_reasons():
    cell = {"agents": 5, "difficulty": "hard"}
    rows = [
        {"method": "ours", **cell, "collisions": 3, "contact_reasons": "parked=1;both_driving=2"},
        {"method": "ours", **cell, "collisions": 0, "contact_reasons": ""},
        {"method": "ours", **cell, "agents": 1, "collisions": 0, "contact_reasons": ""},
        {"method": "ippo", **cell, "collisions": 4, "contact_reasons": ""},
    ]
    (cell,) = contact_summary(rows)
    assert (cell["method"], cell["runs"], cell["contacts"]) == ("ours", 2, 3)
    assert (cell["parked"], cell["both_driving"], cell["into_holding"]) == (1, 2, 0)
    table = contact_table([cell])
    assert table.splitlines()[0].endswith(" | ".join(CONTACT_REASONS) + " |")
    assert "| ours | Hard | 5 | 2 | 1.50 | 1 | 0 | 0 | 0 | 2 |" in table


def test_an_agent_driving_into_a_parked_one_is_counted_so(stand_in_models):
    """Without the safety layer an agent whose straight line runs through an agent parked on its goal
    touches it, and the contact's reason says the parked agent was in the way."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2, max_cycles=40)
    starts, goals = np.array([[0.5, 10.0], [0.9, 11.2]]), np.array([[0.5, 30.0], [0.9, 11.2]])
    ex = execute(env, METHODS["unconstrained_policy"].with_options(safety=False), stand_in_models, None, starts, goals)
    env.close()
    assert ex.collisions >= 1 and sum(ex.contact_reasons.values()) == ex.collisions
    assert ex.contact_reasons.get("parked", 0) >= 1
