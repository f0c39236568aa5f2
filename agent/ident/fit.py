"""How well an identified model reproduces measured data: simulation and Theil's inequality.

The model is simulated open loop from the measured inputs (no output feedback), from an
initial state estimated by least squares, so the fit tests the dynamics rather than a
one-step predictor. The Theil inequality coefficient per output (thesis eq. 5.19; Theil,
*Applied Economic Forecasting*, 1966) is

    TIC_i = √(mean((ŷ_i − y_i)²)) / (√mean(ŷ_i²) + √mean(y_i²)),

0 for a perfect fit, 1 for none; a decent fit has TIC < 0.3 (thesis ref. [67]). Eq. 5.19 as
printed has the two RMS terms under one root; Theil's definition (used here) adds them, which
is what bounds TIC by 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.ident.convert import StateSpace
from agent.ident.okid import Experiment


def simulate(model: StateSpace, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Outputs y(k) = C x(k) + D u(k) of the discrete model driven by u (l × r) from x0."""
    n = model.A.shape[0]
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    states = np.empty((u.shape[0], n))
    for k in range(u.shape[0]):
        states[k] = x
        x = model.A @ x + model.B @ u[k]
    return states @ model.C.T + u @ model.D.T


def free_response_basis(model: StateSpace, length: int) -> np.ndarray:
    """Stacked C A^k for k < length: (length·m × n), the map from x(0) to the free response."""
    n = model.A.shape[0]
    blocks = np.empty((length, model.C.shape[0], n))
    power = model.C.copy()
    for k in range(length):
        blocks[k] = power
        power = power @ model.A
    return blocks.reshape(-1, n)


def estimate_initial_state(model: StateSpace, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x(0) minimising ‖y − ŷ‖² over the record, by linear least squares."""
    forced = simulate(model, u)
    basis = free_response_basis(model, u.shape[0])
    return np.linalg.lstsq(basis, (y - forced).reshape(-1), rcond=None)[0]


def theil(predicted: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Theil inequality coefficient of each column (0 perfect, 1 worst)."""
    err = np.sqrt(np.mean((predicted - measured) ** 2, axis=0))
    scale = np.sqrt(np.mean(predicted**2, axis=0)) + np.sqrt(np.mean(measured**2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(scale > 0, err / scale, 0.0)


@dataclass(frozen=True)
class Fit:
    """Simulated outputs per experiment and the TIC per output over the whole batch."""

    predictions: tuple[np.ndarray, ...]
    initial_states: tuple[np.ndarray, ...]
    tic: np.ndarray  # (m,)

    @property
    def tic_avg(self) -> float:
        return float(np.mean(self.tic))


def fit(model: StateSpace, experiments: Sequence[Experiment]) -> Fit:
    """Simulate `model` on every experiment (own x0 each) and score it with TIC per output."""
    predictions, states = [], []
    for exp in experiments:
        x0 = estimate_initial_state(model, exp.u, exp.y)
        states.append(x0)
        predictions.append(simulate(model, exp.u, x0))
    measured = np.vstack([e.y for e in experiments])
    tic = theil(np.vstack(predictions), measured)
    return Fit(predictions=tuple(predictions), initial_states=tuple(states), tic=tic)
