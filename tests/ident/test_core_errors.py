"""Bad arrays handed straight to the core: typed errors with a reason, never a wrong answer.

Tried: no experiments, NaN in an output, mismatched lengths, experiments with different
channel counts, p < 1, negative regularization, an ERA order outside the Hankel size, a
defective A (Jordan block, no modal basis), a non-positive sample time.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.ident import DataError, Experiment, IdentificationFailed, identify, okid
from agent.ident.era import era
from agent.ident.modal import modal_analysis

GOOD = Experiment(
    u=np.random.default_rng(0).normal(size=(200, 1)),
    y=np.random.default_rng(1).normal(size=(200, 2)),
)


@pytest.mark.parametrize(
    ("batch", "message"),
    [
        ([], "no experiments"),
        ([Experiment(u=GOOD.u, y=np.where(np.arange(200)[:, None] == 7, np.nan, GOOD.y))], "NaN"),
        ([Experiment(u=GOOD.u[:100], y=GOOD.y)], "same number of samples"),
        ([GOOD, Experiment(u=np.ones((50, 2)), y=GOOD.y[:50])], "2 inputs and 2 outputs"),
    ],
)
def test_bad_batches(batch, message):
    with pytest.raises(DataError, match=message):
        okid.as_experiments(batch)


def test_bad_okid_arguments():
    with pytest.raises(DataError, match="at least 1"):
        okid.observer_markov(GOOD, 0)
    with pytest.raises(DataError, match="regularization"):
        okid.observer_markov(GOOD, 2, regularization=-1.0)
    with pytest.raises(DataError, match="sample time"):
        identify(GOOD, 0.0)


def test_era_order_outside_hankel_size():
    Y = np.zeros((100, 1, 1))
    Y[1:] = (0.9 ** np.arange(99))[:, None, None]
    with pytest.raises(DataError, match="outside 1"):
        era(Y, order=0)


def test_defective_model_has_no_modal_decomposition():
    A = np.array([[0.9, 1.0], [0.0, 0.9]])  # Jordan block: one eigenvector for a double root
    with pytest.raises(IdentificationFailed, match="defective"):
        modal_analysis(A, np.ones((2, 1)), np.eye(2), 0.02)
