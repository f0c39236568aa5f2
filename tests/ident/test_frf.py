"""The measured frequency response and coherence (agent/ident/frf.py) on records whose answer
is known: a discrete model driven by white noise or a periodic multisine, with and without
output noise. Bad input tried: a record with one period only (no coherence, said so by nan),
two inputs moving together (not separable: left out, not a wrong column), and a multisine
with too few periods to average (Welch segments instead)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from agent.excitation.signals import multisine
from agent.ident.frf import COHERENCE_MIN, measured, model_response
from agent.ident.okid import Experiment

DT = 0.02
# Two inputs, two outputs: a lightly damped pair (1.2 Hz) and a real pole.
A_C = np.array([[-0.8, 7.5, 0.0], [-7.5, -0.8, 0.0], [0.0, 0.0, -2.0]])
B_C = np.array([[1.0, 0.0], [0.5, 0.2], [0.0, 1.5]])
C = np.array([[1.0, 0.0, 0.3], [0.0, 1.0, 1.0]])
D = np.zeros((2, 2))
A, B, *_ = scipy.signal.cont2discrete((A_C, B_C, C, D), DT, method="zoh")


def simulate(u: np.ndarray) -> np.ndarray:
    x = np.zeros(A.shape[0])
    y = np.empty((u.shape[0], C.shape[0]))
    for k, uk in enumerate(u):
        y[k] = C @ x + D @ uk
        x = A @ x + B @ uk
    return y


def test_two_simultaneous_white_inputs_give_each_column_with_coherence_near_one():
    rng = np.random.default_rng(3)
    u = rng.normal(size=(12_000, 2))
    resp = measured([Experiment(u, simulate(u))], DT)
    assert resp.averaging == "welch"
    assert resp.segments >= 7
    truth = model_response(A, B, C, D, DT, resp.freqs)
    band = (resp.freqs > 0.2) & (resp.freqs < 5.0)
    error = np.abs(resp.H[band] - truth[band]) / np.abs(truth[band])
    assert np.median(error) < 0.05
    assert np.median(resp.coherence[band]) > 0.95
    assert resp.low_coherence(0, 0) < 0.2


def test_output_noise_lowers_the_coherence_and_is_reported():
    rng = np.random.default_rng(4)
    u = rng.normal(size=(12_000, 2))
    y = simulate(u)
    clean = measured([Experiment(u, y)], DT)
    noisy = measured([Experiment(u, y + 3.0 * y.std(axis=0) * rng.normal(size=y.shape))], DT)
    assert np.nanmedian(noisy.coherence) < 0.3 < np.nanmedian(clean.coherence)
    assert noisy.low_coherence(0, 0) > 0.8  # most of the band is below COHERENCE_MIN
    assert COHERENCE_MIN == 0.6


def test_a_periodic_multisine_is_averaged_over_its_periods_at_its_own_lines():
    period = 500  # 10 s at 50 Hz
    lines = np.arange(2, 60, 3)
    u = np.zeros((5 * period, 2))
    u[:, 0] = multisine(lines, period * DT, DT, 5 * period * DT, 1.0)  # the first input only
    rng = np.random.default_rng(5)
    y = simulate(u) + 0.002 * rng.normal(size=(u.shape[0], 2))
    resp = measured([Experiment(u, y)], DT)
    assert resp.averaging == "periods"
    assert resp.segments == 4  # five periods, the first left out
    assert resp.segment_s == pytest.approx(10.0)
    excited = resp.excited(0)
    assert np.allclose(np.sort(resp.freqs[excited]), lines / (period * DT))
    assert not resp.excited(1).any()  # the silent input is never shown
    truth = model_response(A, B, C, D, DT, resp.freqs[excited])
    error = np.abs(resp.H[excited, :, 0] - truth[:, :, 0]) / np.abs(truth[:, :, 0])
    assert np.median(error) < 0.03
    assert np.median(resp.coherence[excited, :, 0]) > 0.9


def test_inputs_that_move_together_are_left_out_and_two_periods_are_not_averaged():
    period = 500
    lines = np.arange(2, 40, 2)
    one = multisine(lines, period * DT, DT, 2 * period * DT, 1.0)
    u = np.column_stack([one, -0.5 * one])  # bad input: one signal on both inputs
    resp = measured([Experiment(u, simulate(u))], DT, period=period)
    assert resp.averaging == "welch"  # two periods are too few to average
    assert not np.isfinite(resp.H).any()  # no column is determined, none is made up
