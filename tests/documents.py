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
