"""The thesis's A.2 lateral flight (examples/a2_lateral.csv) as the agent's recorder rows, for
tests that give the real agent a window to identify."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

A2 = Path(__file__).resolve().parents[1] / "examples" / "a2_lateral.csv"


def a2_rows(channels) -> np.ndarray:
    """The record in the recorder's row layout (`Recorder.channels`: time, values, ages), its
    aileron, rudder, β, p, r and φ filled, everything else missing."""
    with A2.open() as handle:
        table = list(csv.DictReader(handle))
    rows = np.full((len(table), 1 + 2 * len(channels)), np.nan)
    rows[:, 0] = [float(r["time"]) for r in table]
    for name in ("aileron", "rudder", "beta", "p", "r", "phi"):
        rows[:, 1 + channels.index(name)] = [float(r[name]) for r in table]
    return rows
