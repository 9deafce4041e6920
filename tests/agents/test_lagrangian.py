"""The Lagrange multiplier: direction of the update and projection onto lambda >= 0."""
import pytest
import torch as th

from agents.lagrangian import LagrangeMultiplier


def test_defaults_follow_the_paper():
    lam = LagrangeMultiplier()
    assert lam.value == 0.0
    assert lam.learning_rate == pytest.approx(0.035)
    assert lam.cost_limit == 10.0


def test_cost_above_limit_raises_lambda_by_lr_times_violation():
    lam = LagrangeMultiplier(cost_limit=10.0, learning_rate=0.5)
    assert lam.update([14.0, 16.0]) == pytest.approx(0.5 * (15.0 - 10.0))
    assert lam.update(12.0) == pytest.approx(2.5 + 0.5 * 2.0)
    assert lam.n_updates == 2


def test_cost_below_limit_lowers_lambda_and_projects_to_zero():
    lam = LagrangeMultiplier(cost_limit=10.0, learning_rate=0.1, initial_value=1.0)
    assert lam.update(5.0) == pytest.approx(0.5)
    assert lam.update(0.0) == 0.0  # 0.5 - 1.0 would be negative
    assert lam.update(0.0) == 0.0
    assert float(lam) == 0.0


def test_cap_and_penalized_objective():
    lam = LagrangeMultiplier(cost_limit=0.0, learning_rate=10.0, max_value=3.0)
    assert lam.update(1.0) == 3.0
    d, c = th.tensor([4.0]), th.tensor([8.0])
    assert float(lam.penalized(d, c)) == pytest.approx((4.0 + 3.0 * 8.0) / 4.0)


@pytest.mark.parametrize("kwargs", [{"cost_limit": -1.0}, {"learning_rate": float("nan")},
                                    {"initial_value": -0.1}, {"initial_value": 2.0, "max_value": 1.0}])
def test_invalid_settings_raise(kwargs):
    with pytest.raises(ValueError):
        LagrangeMultiplier(**kwargs)


def test_invalid_costs_raise():
    lam = LagrangeMultiplier()
    with pytest.raises(ValueError, match="at least one"):
        lam.update([])
    with pytest.raises(ValueError, match="finite"):
        lam.update([1.0, float("inf")])
