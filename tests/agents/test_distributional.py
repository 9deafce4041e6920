"""The categorical Bellman targets, checked by hand."""
import numpy as np
import pytest
import torch as th

from agents.distributional import (
    categorical_projection,
    cost_support,
    distance_support,
    expected_value,
    shift_distance_target,
)


def test_supports():
    assert distance_support(4).tolist() == [1.0, 2.0, 3.0, 4.0]
    assert cost_support(5, 4.0).tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    with pytest.raises(ValueError, match="n_bins=1"):
        distance_support(1)
    with pytest.raises(ValueError, match="cost_max"):
        cost_support(5, 0.0)


def test_distance_shift_moves_mass_one_bin_and_last_bin_absorbs():
    p = th.tensor([[0.1, 0.2, 0.3, 0.4]])
    out = shift_distance_target(p, th.tensor([0.0]))
    assert th.allclose(out, th.tensor([[0.0, 0.1, 0.2, 0.7]]))
    # expected distance grows by exactly one step when nothing overflows
    q = th.tensor([[0.5, 0.5, 0.0, 0.0]])
    sup = distance_support(4)
    shifted = shift_distance_target(q, th.tensor([False]))
    assert float(shifted @ sup[:, None]) == pytest.approx(float(q @ sup[:, None]) + 1.0)


def test_distance_shift_terminal_is_one_step():
    p = th.tensor([[0.1, 0.2, 0.3, 0.4], [0.25, 0.25, 0.25, 0.25]])
    out = shift_distance_target(p, th.tensor([1.0, 0.0]))
    assert out[0].tolist() == [1.0, 0.0, 0.0, 0.0]
    assert out[1].tolist() == pytest.approx([0.0, 0.25, 0.25, 0.5])
    assert th.allclose(out.sum(-1), th.ones(2))


def test_distance_shift_broadcasts_over_ensemble_axis():
    p = th.softmax(th.randn(3, 5, 6), -1)
    dones = th.tensor([0.0, 1.0, 0.0, 0.0, 1.0]).expand(3, -1)
    out = shift_distance_target(p, dones)
    assert out.shape == (3, 5, 6)
    assert th.allclose(out[:, 1, 0], th.ones(3))
    assert th.allclose(out[:, 0, 1:-1], p[:, 0, :-2])


def test_c51_projection_hand_cases():
    sup = cost_support(5, 4.0)  # atoms 0, 1, 2, 3, 4
    one_at_1 = th.tensor([[0.0, 1.0, 0.0, 0.0, 0.0]])
    # 0.5 + 1 = 1.5: half on atom 1, half on atom 2
    out = categorical_projection(one_at_1, th.tensor([0.5]), th.tensor([0.0]), sup)
    assert out[0].tolist() == pytest.approx([0.0, 0.5, 0.5, 0.0, 0.0])
    # exactly on an atom: 2 + 1 = 3
    out = categorical_projection(one_at_1, th.tensor([2.0]), th.tensor([0.0]), sup)
    assert out[0].tolist() == pytest.approx([0.0, 0.0, 0.0, 1.0, 0.0])
    # terminal: only the reward counts, 0.25 -> 3/4 on atom 0, 1/4 on atom 1
    out = categorical_projection(one_at_1, th.tensor([0.25]), th.tensor([1.0]), sup)
    assert out[0].tolist() == pytest.approx([0.75, 0.25, 0.0, 0.0, 0.0])
    # beyond the support: clipped to the last atom
    out = categorical_projection(one_at_1, th.tensor([10.0]), th.tensor([0.0]), sup)
    assert out[0].tolist() == pytest.approx([0.0, 0.0, 0.0, 0.0, 1.0])
    # discount 0.5 of a spread distribution: atoms 2 and 4 -> 1 and 2, plus reward 1 -> 2 and 3
    spread = th.tensor([[0.0, 0.0, 0.5, 0.0, 0.5]])
    out = categorical_projection(spread, th.tensor([1.0]), th.tensor([0.0]), sup, gamma=0.5)
    assert out[0].tolist() == pytest.approx([0.0, 0.0, 0.5, 0.5, 0.0])


def test_c51_projection_conserves_mass_and_mean_inside_support():
    g = th.Generator().manual_seed(0)
    sup = cost_support(40, 40.0)
    p = th.softmax(th.randn(3, 256, 40, generator=g), -1)
    p[..., 35:] = 0.0  # no mass near the top, so r + Z' (r <= 2) never leaves the support
    p = p / p.sum(-1, keepdim=True)
    r = th.rand(3, 256, generator=g) * 2.0
    dones = (th.rand(3, 256, generator=g) < 0.3).float()
    out = categorical_projection(p, r, dones, sup)
    assert th.allclose(out.sum(-1), th.ones(3, 256), atol=1e-5)
    assert (out >= 0).all()
    # linear interpolation between neighbouring atoms preserves the mean
    expect = r + (1 - dones) * (p * sup).sum(-1)
    assert th.allclose((out * sup).sum(-1), expect, atol=1e-4)
    # clipped mass ends on the last atom and is not lost
    big = categorical_projection(p, th.full((3, 256), 39.0), th.zeros(3, 256), sup)
    assert th.allclose(big.sum(-1), th.ones(3, 256), atol=1e-5)
    assert np.all(big[..., -1].numpy() > 0.5)


def test_expected_value():
    logits = th.log(th.tensor([[0.5, 0.5, 0.0 + 1e-12]]))
    assert float(expected_value(logits, distance_support(3))) == pytest.approx(1.5, abs=1e-6)
