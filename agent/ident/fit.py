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

# Samples per block of the lifted simulation (below): long enough that the per-block Python
# work is amortised, short enough that the block Toeplitz matrix stays small.
BLOCK_MIN, BLOCK_MAX = 8, 96


def _block_length(samples: int) -> int:
    return int(np.clip(np.sqrt(samples), BLOCK_MIN, BLOCK_MAX))


def _powers(A: np.ndarray, count: int) -> np.ndarray:
    """A⁰ … A^(count−1) stacked: (count × n × n)."""
    n = A.shape[0]
    out = np.empty((count, n, n))
    out[0] = np.eye(n)
    for k in range(1, count):
        out[k] = out[k - 1] @ A
    return out


def simulate(model: StateSpace, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Outputs y(k) = C x(k) + D u(k) of the discrete model driven by u (l × r) from x0.

    Exact, but lifted to blocks of L samples so that the Python loop runs l/L times: within a
    block, y = O x(start) + T u_block with O = [C; CA; …; CA^(L−1)] and T the block Toeplitz
    matrix of the Markov parameters; between blocks x ← A^L x + [A^(L−1)B … B] u_block.
    """
    u = np.asarray(u, dtype=float)
    length, r = u.shape
    n, m = model.A.shape[0], model.C.shape[0]
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    if length == 0:
        return np.zeros((0, m))
    L = min(_block_length(length), length)
    blocks = -(-length // L)
    padded = np.zeros((blocks * L, r))
    padded[:length] = u
    powers = _powers(model.A, L + 1)
    O = (model.C @ powers[:L]).reshape(L * m, n)  # (L·m × n)
    markov = model.C @ powers[: L - 1] @ model.B  # C A^(k) B, k < L−1: (L−1 × m × r)
    # Block (k, l) of T is D at lag k − l = 0, C A^(k−l−1) B above, zero below.
    stack = np.concatenate([np.zeros((1, m, r)), model.D[None], markov])
    lag = np.arange(L)[:, None] - np.arange(L)[None, :]
    T = stack[np.where(lag >= 0, lag + 1, 0)].transpose(0, 2, 1, 3).reshape(L * m, L * r)
    reach = (powers[L - 1 :: -1][:L] @ model.B).transpose(1, 0, 2).reshape(n, L * r)
    AL = powers[L]
    U = padded.reshape(blocks, L * r)
    starts = np.empty((blocks, n))
    for b in range(blocks):
        starts[b] = x
        x = AL @ x + reach @ U[b]
    y = starts @ O.T + U @ T.T
    return y.reshape(blocks * L, m)[:length]


def simulate_states(model: StateSpace, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """States x(k) (l × n) of the discrete model driven by u from x0."""
    n, r = model.B.shape
    return simulate(StateSpace(model.A, model.B, np.eye(n), np.zeros((n, r))), u, x0)


def state_convolution(A: np.ndarray, C: np.ndarray, z: np.ndarray) -> np.ndarray:
    """out[k, :, i, j] = Σ_{t<k} (C A^(k−1−t))[:, i] z[t, j]: (l × m × n × q).

    The output, at every step, of the system (A, e_i, C) driven by each scalar signal z_j: the
    sensitivity of a simulated output to the (i, j) entry of A (with z = states) or of B (with
    z = inputs). Lifted to blocks like `simulate`.
    """
    z = np.asarray(z, dtype=float)
    return state_convolution_from(A, C, z, np.zeros((A.shape[0], A.shape[0], z.shape[1])))[0]


def state_convolution_from(
    A: np.ndarray, C: np.ndarray, z: np.ndarray, start: np.ndarray, block: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """`state_convolution` continued from an earlier stretch of the same signals: `start`
    (n × n × q) is the state Σ_{t<0} A^(−1−t) e_i z[t, j] the earlier samples left, and the
    second result the state after these samples. `block`: the lifted block length (default
    `_block_length(length)`); the end state is exact when the length is a multiple of it (the
    padding of a last partial block would advance it), so a caller streaming a record in
    pieces gives one that divides them."""
    length, q = z.shape
    n, m = A.shape[0], C.shape[0]
    if length == 0:
        return np.zeros((0, m, n, q)), start
    L = min(block or _block_length(length), length)
    blocks = -(-length // L)
    padded = np.zeros((blocks * L, q))
    padded[:length] = z
    powers = _powers(A, L + 1)
    obs = (C @ powers[:L]).reshape(L * m, n)  # C A^k, k < L
    markov = C @ powers[: L - 1]  # C A^k, k < L−1: (L−1 × m × n)
    stack = np.concatenate([np.zeros((1, m, n)), markov])
    lag = np.arange(L)[:, None] - np.arange(L)[None, :]
    T = stack[np.where(lag >= 1, lag, 0)]  # block (k, t): C A^(k−t−1) for k > t
    T = T.transpose(0, 2, 3, 1).reshape(L * m * n, L)  # (k, m, i) × t
    reach = powers[L - 1 :: -1][:L].transpose(1, 2, 0).reshape(n * n, L)  # A^(L−1−t)
    Z = padded.reshape(blocks, L, q)
    forced = (T @ Z.transpose(1, 0, 2).reshape(L, blocks * q)).reshape(L, m, n, blocks, q)
    start = np.array(start, dtype=float)
    free = np.empty((blocks, L * m, n * q))
    for b in range(blocks):
        free[b] = obs @ start.reshape(n, n * q)
        start = (powers[L] @ start.reshape(n, n * q)).reshape(n, n, q) + (reach @ Z[b]).reshape(
            n, n, q
        )
    out = forced.transpose(3, 0, 1, 2, 4) + free.reshape(blocks, L, m, n, q)
    return out.reshape(blocks * L, m, n, q)[:length], start


def free_response_basis(model: StateSpace, length: int) -> np.ndarray:
    """Stacked C A^k for k < length: (length·m × n), the map from x(0) to the free response."""
    n, m = model.A.shape[0], model.C.shape[0]
    if length == 0:
        return np.zeros((0, n))
    L = min(_block_length(length), length)
    blocks = -(-length // L)
    powers = _powers(model.A, L + 1)
    O = (model.C @ powers[:L]).reshape(L * m, n)
    out = np.empty((blocks, L * m, n))
    step = np.eye(n)
    for b in range(blocks):
        out[b] = O @ step
        step = powers[L] @ step
    return out.reshape(blocks * L * m, n)[: length * m]


def observability_gramian(A: np.ndarray, C: np.ndarray, length: int) -> np.ndarray:
    """Σ_{k<length} (A^k)ᵀ Cᵀ C A^k by doubling (log₂ length matrix products)."""
    n = A.shape[0]
    total, offset = np.zeros((n, n)), np.eye(n)
    block, power = C.T @ C, A.copy()  # block: the sum over 2^j steps; power: A^(2^j)
    remaining = length
    while remaining:
        if remaining & 1:
            total += offset.T @ block @ offset
            offset = power @ offset
        remaining >>= 1
        if remaining:
            block = block + power.T @ block @ power
            power = power @ power
    return total


def estimate_initial_state(model: StateSpace, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x(0) minimising ‖y − ŷ‖² over the record, by linear least squares.

    The normal equations W x(0) = Σ_k (A^k)ᵀ Cᵀ e(k) (e = y minus the forced response) are
    formed without the (length·m × n) free-response matrix: W is the observability Gramian
    (by doubling) and the right side is the end state of the adjoint system driven by e in
    reverse time. Solved by eigen-decomposition with tiny eigenvalues (unobservable
    directions) dropped. A strongly unstable model overflows over a long record; its x(0) is
    then zero (its fit is worthless anyway, and `fit` scores it so).
    """
    n = model.A.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        error = y - simulate(model, u)
        adjoint = StateSpace(model.A.T, model.C.T, np.eye(n), np.zeros((n, model.C.shape[0])))
        reverse = np.vstack([error[::-1], np.zeros((1, error.shape[1]))])
        rhs = simulate(adjoint, reverse)[-1]
        gramian = observability_gramian(model.A, model.C, u.shape[0])
    if not (np.all(np.isfinite(gramian)) and np.all(np.isfinite(rhs))):
        return np.zeros(n)
    gramian = 0.5 * (gramian + gramian.T)
    values, vectors = np.linalg.eigh(gramian)
    keep = values > 1e-12 * max(values.max(), 0.0)
    if not keep.any():
        return np.zeros(n)
    return vectors[:, keep] @ ((vectors[:, keep].T @ rhs) / values[keep])


def theil(predicted: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Theil inequality coefficient of each column (0 perfect, 1 worst)."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        err = np.sqrt(np.mean((predicted - measured) ** 2, axis=0))
        scale = np.sqrt(np.mean(predicted**2, axis=0)) + np.sqrt(np.mean(measured**2, axis=0))
        tic = np.where(scale > 0, err / scale, 0.0)
    return np.where(np.isfinite(tic), tic, 1.0)  # an overflowing prediction fits not at all


@dataclass(frozen=True, kw_only=True)
class Fit:
    """Simulated outputs per experiment and the TIC per output over the whole batch."""

    predictions: tuple[np.ndarray, ...]
    initial_states: tuple[np.ndarray, ...]
    tic: np.ndarray  # (m,)

    @property
    def tic_avg(self) -> float:
        return float(np.mean(self.tic))


def with_output_biases(model: StateSpace) -> StateSpace:
    """`model` with a constant bias on each output as states of their own (A = I, no input):
    estimated with its initial state (`fit`), they take a record's offsets from its trim (it
    did not start trimmed, or a sensor's zero moved) out of the score, as a validation does."""
    n, m = model.A.shape[0], model.C.shape[0]
    r = model.B.shape[1]
    A = np.block([[model.A, np.zeros((n, m))], [np.zeros((m, n)), np.eye(m)]])
    B = np.vstack([model.B, np.zeros((m, r))])
    C = np.hstack([model.C, np.eye(m)])
    return StateSpace(A, B, C, model.D)


def validation_fit(model: StateSpace, experiments: Sequence[Experiment]) -> Fit:
    """`model` scored as a validation scores it: each record's initial state and a constant
    bias on each output estimated by least squares (`with_output_biases`), then the TIC."""
    return fit(with_output_biases(model), experiments)


def fit(
    model: StateSpace,
    experiments: Sequence[Experiment],
    initial_states: Sequence[np.ndarray] | None = None,
) -> Fit:
    """Simulate `model` on every experiment (own x0 each: estimated, or `initial_states`
    when given) and score it with TIC per output."""
    predictions, states = [], []
    for k, exp in enumerate(experiments):
        if initial_states is None:
            x0 = estimate_initial_state(model, exp.u, exp.y)
        else:
            x0 = np.asarray(initial_states[k], dtype=float)
        states.append(x0)
        with np.errstate(over="ignore", invalid="ignore"):
            predictions.append(simulate(model, exp.u, x0))
    measured = np.vstack([e.y for e in experiments])
    predicted = np.vstack(predictions)
    if not np.all(np.isfinite(predicted)):
        # The simulation diverged: as bad a fit as TIC can say.
        return Fit(
            predictions=tuple(predictions),
            initial_states=tuple(states),
            tic=np.ones(measured.shape[1]),
        )
    tic = theil(predicted, measured)
    return Fit(predictions=tuple(predictions), initial_states=tuple(states), tic=tic)
