"""The exact discrete model of a continuous one observed through block means
(agent.ident.lifted), and the refinement that fits it.

Known answers: the record's own discretisation (exact for its hold) simulated sample by sample
and averaged in blocks; finite differences of the lifted matrices; a noise-free record of a
known fast first-order system, its pole recovered from block means.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident.convert import StateSpace, discretize_hold
from agent.ident.fit import simulate
from agent.ident.lifted import block_means, blocks_jacobian, discretize_blocks, lift
from agent.ident.okid import Experiment
from agent.ident.refine import refine


def _random_model(seed: int, n: int = 3, m: int = 2, r: int = 2) -> StateSpace:
    rng = np.random.default_rng(seed)
    return StateSpace(
        rng.normal(size=(n, n)) - 2.0 * np.eye(n),
        rng.normal(size=(n, r)),
        rng.normal(size=(m, n)),
        rng.normal(size=(m, r)),
    )


@pytest.mark.parametrize("hold", ["zoh", "foh"])
@pytest.mark.parametrize("block", [1, 3, 8])
def test_the_lifted_model_gives_the_block_means_of_the_samples(hold, block):
    model, dt = _random_model(1), 0.01
    rng = np.random.default_rng(2)
    u = rng.normal(size=(401, 2))
    u[0] = 0.0  # from rest, so the first-order hold's state (x − Γ2 u) starts at x = 0 too
    samples = simulate(
        discretize_hold(model.A, model.B, model.C, model.D, dt, hold), u, np.zeros(3)
    )
    lifted = discretize_blocks(model, dt, hold, block)
    means = simulate(lifted, lift(u, block), np.zeros(3))
    expected = block_means(samples, block)
    assert means.shape == expected.shape == ((401 - 1) // block, 2)
    assert np.allclose(means, expected, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_the_lifted_model_s_jacobian_matches_finite_differences(hold):
    model, dt, block = _random_model(3), 0.02, 4
    n, r, m = 3, 2, 2
    sizes = np.cumsum([n * n, n * r, m * n])

    def flat(v: np.ndarray) -> np.ndarray:
        a, b, c, d = np.split(v, sizes)
        lifted = discretize_blocks(
            StateSpace(a.reshape(n, n), b.reshape(n, r), c.reshape(m, n), d.reshape(m, r)),
            dt,
            hold,
            block,
        )
        return np.concatenate([x.ravel() for x in (lifted.A, lifted.B, lifted.C, lifted.D)])

    v0 = np.concatenate([x.ravel() for x in (model.A, model.B, model.C, model.D)])
    step = 1e-6
    numeric = np.column_stack(
        [(flat(v0 + step * e) - flat(v0 - step * e)) / (2 * step) for e in np.eye(v0.size)]
    )
    _, chain = blocks_jacobian(model, dt, hold, block)
    assert np.allclose(chain, numeric, atol=1e-8)
    # Entries not marked as moving get no derivative.
    moving = np.zeros(n * n + n * r, dtype=bool)
    moving[[0, 4, n * n + 1]] = True
    _, part = blocks_jacobian(model, dt, hold, block, moving)
    assert np.allclose(part[:, np.flatnonzero(moving)], numeric[:, np.flatnonzero(moving)])
    assert not part[:, np.flatnonzero(~moving)[:5]].any()


def test_a_fast_mode_is_found_from_block_means_exactly():
    """A roll-like first-order mode of 12 1/s, a record at 100 Hz of step inputs, fitted from
    means over blocks of 8 samples (12.5 Hz, the mode crossing its time constant within a
    block): the exact model recovers the pole; the block means taken as the samples of a
    first-order hold between them (what the refinement did before) miss it by percents, as
    the glider's roll in the benchmark."""
    dt, block = 0.01, 8
    truth = StateSpace(np.array([[-12.0]]), np.array([[30.0]]), np.eye(1), np.zeros((1, 1)))
    u = np.zeros((1601, 1))
    for start, level in ((50, 1.0), (130, -1.0), (210, 0.5), (250, -0.5), (700, 1.0)):
        u[start:] = level
    y = simulate(discretize_hold(truth.A, truth.B, truth.C, truth.D, dt, "zoh"), u, np.zeros(1))
    start = StateSpace(np.array([[-8.0]]), np.array([[20.0]]), np.eye(1), np.zeros((1, 1)))
    exact = refine(
        start,
        dt,
        [Experiment(u, y)],
        output_coordinates=True,
        estimate_d=False,
        hold="zoh",
        block=block,
    )
    assert exact.continuous.A[0, 0] == pytest.approx(-12.0, rel=1e-6)
    assert exact.dt == pytest.approx(dt * block)
    approximate = refine(
        start,
        dt * block,
        [Experiment(block_means(u, block), block_means(y, block))],
        output_coordinates=True,
        estimate_d=False,
        hold="foh",
    )
    assert abs(approximate.continuous.A[0, 0] / -12.0 - 1.0) > 0.02
