"""A result document to build tests on: a lateral model (aileron, rudder → β, p, r, φ) at 50 Hz
with every field its neutral value, changed by keywords."""

from __future__ import annotations

import numpy as np

from agent.ident.document import PreprocessingDocument, ResultDocument

INPUTS = ("aileron", "rudder")
OUTPUTS = ("beta", "p", "r", "phi")


def lateral_document(**changes) -> ResultDocument:
    """The neutral document with `changes` (field → value) applied and validated."""
    zeros = lambda rows, cols: np.zeros((rows, cols)).tolist()  # noqa: E731
    fields = {
        "dt": 0.02,
        "order": 4,
        "inputs": list(INPUTS),
        "outputs": list(OUTPUTS),
        "A": np.eye(4).tolist(),
        "B": zeros(4, 2),
        "C": np.eye(4).tolist(),
        "D": zeros(4, 2),
        "Ac": None,
        "Bc": None,
        "stable": True,
        "tic": dict.fromkeys(OUTPUTS, 0.01),
        "tic_avg": 0.01,
        "modes": [],
        "method": "time",
        "coordinates": "outputs",
        "continuous": None,
        "preprocessing": PreprocessingDocument(
            record_dt=0.02,
            decimation=1,
            band_hz=2.0,
            held_inputs_shifted=False,
            smoothing_s=None,
            dropped_samples_per_end=0,
        ),
    }
    return ResultDocument(**(fields | changes))


def continuous_document(A, B, inputs, outputs) -> ResultDocument:
    """A whole-aircraft-shaped document of a continuous model ẋ = A x + B u in output
    coordinates (a state per output first, then any others: engine lags), as `sysid tune` and
    the onboard gains design take it."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    n, m, p = A.shape[0], B.shape[1], len(outputs)
    C, D = np.eye(n)[:p].tolist(), np.zeros((p, m)).tolist()
    return lateral_document(
        order=n,
        inputs=list(inputs),
        outputs=list(outputs),
        A=np.eye(n).tolist(),
        B=np.zeros((n, m)).tolist(),
        C=C,
        D=D,
        Ac=A.tolist(),
        Bc=B.tolist(),
        tic=dict.fromkeys(outputs, 0.05),
        tic_avg=0.05,
        method="aircraft",
        continuous={"A": A.tolist(), "B": B.tolist(), "C": C, "D": D},
    )
