"""Continuous-time conversion, output coordinates, simulation fit and TIC."""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident import ContinuousConversionError, reference
from agent.ident.convert import (
    StateSpace,
    discretize,
    output_coordinates_transform,
    to_continuous,
)
from agent.ident.era import era, suggest_order
from agent.ident.fit import estimate_initial_state, fit, simulate, theil
from agent.ident.okid import Experiment


def test_continuous_round_trip_including_an_integrator():
    Ac = np.array([[0.0, 1.0], [0.0, -2.0]])  # an integrator: discrete eigenvalue exactly 1
    Bc = np.array([[0.0], [3.0]])
    A, B = discretize(Ac, Bc, 0.02)
    Ac2, Bc2 = to_continuous(A, B, 0.02)
    assert np.allclose(Ac2, Ac, atol=1e-10)
    assert np.allclose(Bc2, Bc, atol=1e-10)


def test_negative_real_discrete_eigenvalue_is_a_clear_error():
    A = np.diag([0.9, -0.5])
    with pytest.raises(ContinuousConversionError, match=r"-0\.5 on the negative real axis"):
        to_continuous(A, np.ones((2, 1)), 0.02)


def test_output_coordinates_only_when_every_state_is_measured():
    assert output_coordinates_transform(np.eye(3)[:2]) is None  # m < n
    assert output_coordinates_transform(np.array([[1.0, 1.0], [1.0, 1.0 + 1e-12]])) is None
    C = np.array([[2.0, 1.0], [0.0, 1.0]])
    assert np.array_equal(output_coordinates_transform(C), C)


def test_suggested_order_is_the_largest_gap():
    assert suggest_order(np.array([10, 8, 5, 1e-3, 9e-4, 8e-4]), 5) == 3
    assert suggest_order(np.array([10, 8, 5, 1e-3, 9e-4, 1e-16]), 5) == 5  # rank 5: exact
    assert suggest_order(np.array([10, 8, 5, 4, 1e-15, 1e-16]), 5) == 4
    # with structural rank 4 (an OKID model with p·m = 4) the gap into the zeros is ignored
    assert suggest_order(np.array([10, 1, 0.9, 0.8, 1e-16]), 4, structural_rank=4) == 1


def test_era_rejects_an_order_above_the_hankel_rank():
    Y = np.zeros((100, 1, 1))
    Y[1:] = (0.9 ** np.arange(99))[:, None, None]  # a first-order system
    assert era(Y).order == 1
    with pytest.raises(Exception, match="rank 1"):
        era(Y, order=3)


def test_tic_bounds():
    y = np.random.default_rng(0).normal(size=(200, 2))
    assert np.allclose(theil(y, y), 0.0)
    assert np.allclose(theil(np.zeros_like(y), y), 1.0)
    assert np.allclose(theil(-y, y), 1.0)


def test_initial_state_is_estimated_from_the_free_response():
    model = reference.LATERAL
    A, B = discretize(model.A, model.B, 0.02)
    ss = StateSpace(A, B, np.eye(4), np.zeros((4, 2)))
    x0 = np.array([0.05, -0.1, 0.02, 0.1])
    u = reference.multisine_inputs(model.inputs, 0.02, 10.0, 5, (0.1, 2.0))
    y = simulate(ss, u, x0)
    assert np.allclose(estimate_initial_state(ss, u, y), x0, atol=1e-10)
    result = fit(ss, [Experiment(u=u, y=y)])
    assert result.tic_avg < 1e-10
