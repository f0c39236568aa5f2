"""Batch identification: several experiments, one model, no regression row across a seam.

Experiment 1 moves only the elevator, experiment 2 only the throttle (each starting from a
different, non-trim state). Alone, neither determines the other input's column of B; together
they recover the whole A.3 longitudinal model. Gluing them end to end into one record puts
regression rows across the seam, which a correct batch never does.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident import ConstantChannelError, Experiment, Settings, identify, okid, reference
from agent.ident.convert import discretize
from tests.conftest import DT, matched_relative_errors

MODEL = reference.LONGITUDINAL


def _experiment(active: int, seed: int, x0: np.ndarray) -> Experiment:
    u_full = reference.multisine_inputs(MODEL.inputs, DT, 20.0, seed, (0.05, 2.0))
    u = np.zeros_like(u_full)
    u[:, active] = u_full[:, active]
    y = reference.simulate(MODEL, u, DT, x0=x0)
    return Experiment(u=u, y=y)


@pytest.fixture(scope="module")
def pair():
    elevator_only = _experiment(1, seed=3, x0=np.array([0.5, 0.01, 0.02, -0.01]))
    throttle_only = _experiment(0, seed=4, x0=np.array([-0.3, -0.02, 0.01, 0.02]))
    return elevator_only, throttle_only


def _b_error(result) -> np.ndarray:
    """Relative error of each column of the identified continuous B."""
    B = result.continuous.B
    return np.abs(B - MODEL.B).max(axis=0) / np.abs(MODEL.B).max(axis=0)


def test_batch_recovers_the_model_neither_experiment_gives_alone(pair):
    settings = Settings(markov=2, order=4)
    batch = identify(list(pair), DT, settings=settings, input_names=MODEL.inputs)
    assert batch.coordinates == "outputs"
    assert np.abs(batch.continuous.A - MODEL.A).max() / np.abs(MODEL.A).max() < 1e-6
    assert _b_error(batch).max() < 1e-6


@pytest.mark.parametrize(("alone", "missing"), [(0, "throttle"), (1, "elevator")])
def test_one_experiment_alone_is_refused_and_underdetermined(pair, alone, missing):
    with pytest.raises(ConstantChannelError, match=f"input '{missing}' is constant"):
        identify(pair[alone], DT, settings=Settings(markov=2), input_names=MODEL.inputs)
    omp = okid.observer_markov(pair[alone], 2)
    columns = okid.regression_columns(2, 4, 2, estimate_d=False)
    assert omp.rank < columns  # the silent input's columns carry nothing
    both = okid.observer_markov(list(pair), 2)
    assert both.rank > omp.rank


def _discrete_eigenvalue_error(result) -> float:
    Ad, _ = discretize(MODEL.A, MODEL.B, DT)
    truth = np.linalg.eigvals(Ad)
    return float(matched_relative_errors(np.linalg.eigvals(result.discrete.A), truth).max())


def test_no_regression_row_straddles_two_experiments(pair):
    phi, _ = okid.build_regression(list(pair), p=3, estimate_d=False)
    assert phi.shape[0] == sum(e.length - 3 for e in pair)
    glued = Experiment(u=np.vstack([e.u for e in pair]), y=np.vstack([e.y for e in pair]))
    settings = Settings(markov=2, order=4)
    seam = identify(glued, DT, settings=settings)
    batch = identify(list(pair), DT, settings=settings)
    assert _discrete_eigenvalue_error(batch) < 1e-9
    assert _discrete_eigenvalue_error(seam) > 1e-4


@pytest.mark.parametrize("estimate_d", [False, True])
def test_the_streamed_regression_is_the_whole_records_least_squares(pair, monkeypatch, estimate_d):
    """OKID's least squares is streamed block by block (memory: one block of Φ, not the
    record's). With blocks of 7 rows (many seams inside and across the two experiments) the
    Markov parameters, singular values and residuals are the one-shot solution's."""
    batch = [Experiment(e.u + 0.01 * np.sin(np.arange(e.length))[:, None], e.y) for e in pair]
    whole = okid.observer_markov(batch, 3, estimate_d=estimate_d)
    phi, target = okid.build_regression(batch, 3, estimate_d)
    monkeypatch.setattr(okid, "REGRESSION_BLOCK", 7)
    streamed = okid.observer_markov(batch, 3, estimate_d=estimate_d)
    assert streamed.rows == whole.rows == phi.shape[0]
    assert np.allclose(streamed.Ybar1, whole.Ybar1, rtol=0, atol=1e-9)
    assert np.allclose(streamed.Ybar2, whole.Ybar2, rtol=0, atol=1e-9)
    assert np.allclose(streamed.D, whole.D, rtol=0, atol=1e-9)
    assert np.allclose(streamed.singular_values, whole.singular_values, rtol=1e-9)
    # Against plain least squares on the whole Φ, formed at once.
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    residual = np.sqrt(np.mean((target - phi @ theta) ** 2, axis=0))
    assert np.allclose(streamed.residual_rms, residual, rtol=1e-6, atol=1e-12)
