"""A continuous model observed through block means: the exact discrete model of averaged data.

A fit at a lower rate than the record's averages the samples in blocks of `block` first (a
low-pass that leaves the modes, and fewer samples per step of the search). The usual model
of such data discretises the continuous one at the block interval with the block means as
held (or linear) inputs: not the response of the aircraft to what it was flown with when a
mode crosses much of its time constant within a block, and in measure as the block grows
(agent.ident.aircraft.predictor: the glider's roll 9–23 % off at 12.5 Hz, 6 % at 50).

Exactly: with the record's own hold between its samples, x(k+1) = Φ x(k) + E0 u(k) + E1 u(k+1)
at the record's step (zero-order hold: E0 = Γ, E1 = 0; first-order: E0 = Γa − Γ2, E1 = Γ2,
agent.ident.convert.hold_block), so over block j of samples js … js + s − 1

    x(js + i) = Φ^i x_j + Σ_l T_il u(js + l),
    T_il = Φ^(i−1−l) E0 [l < i] + Φ^(i−l) E1 [1 ≤ l ≤ i],

and the block's state and mean output are those of a discrete model whose inputs are the
block's s + 1 samples (its own and the next block's first, `lift`):

    x_(j+1) = Φ^s x_j + [T_s0 … T_ss] U_j,   ȳ_j = C M x_j + (C [W_0 … W_s] + D L) U_j,

M = (1/s) Σ_(i<s) Φ^i, W_l = (1/s) Σ_(i<s) T_il, L = (1/s)[I … I 0] (the lifted, or
block-pulse, model of multirate control: Khargonekar, Poolla & Tannenbaum, *IEEE TAC* 30,
1985). Noise on it stays a linear time-invariant system at the block rate, so its innovation
form (agent.ident.refine) is exact too.
"""

from __future__ import annotations

import numpy as np

from agent.ident.convert import StateSpace, hold_derivatives


def lift(u: np.ndarray, block: int) -> np.ndarray:
    """Each whole block's s + 1 input samples side by side (the next block's first sample
    last): (blocks, (s + 1)·r), blocks = (samples − 1) // s."""
    count = (u.shape[0] - 1) // block
    index = np.arange(count)[:, None] * block + np.arange(block + 1)[None, :]
    return u[index].reshape(count, -1)


def block_means(y: np.ndarray, block: int) -> np.ndarray:
    """The means of `y`'s rows over the blocks `lift` keeps."""
    count = (y.shape[0] - 1) // block
    return y[: count * block].reshape(count, block, y.shape[1]).mean(axis=1)


def discretize_blocks(model: StateSpace, dt: float, hold: str, block: int) -> StateSpace:
    """The discrete model of `model`'s block means (module text); `dt` the record's step."""
    return blocks_jacobian(model, dt, hold, block, jacobian=False)[0]


def blocks_jacobian(
    model: StateSpace,
    dt: float,
    hold: str,
    block: int,
    moving: np.ndarray | None = None,
    *,
    jacobian: bool = True,
) -> tuple[StateSpace, np.ndarray | None]:
    """The block-mean model (`discretize_blocks`) and ∂[vec Φb, vec Bb, vec Cb, vec Db] /
    ∂[vec Ac, vec Bc, vec C, vec D] (row-major), the derivatives along the entries of
    [vec Ac, vec Bc] that `moving` does not mark left zero (as
    agent.ident.refine.discretization_jacobian)."""
    A, B, C, D = model.A, model.B, model.C, model.D
    n, r = B.shape
    m = C.shape[0]
    s = block
    k = n * n + n * r
    mask = np.ones(k, dtype=bool) if moving is None else np.asarray(moving, dtype=bool)
    if not jacobian:
        mask = np.zeros(k, dtype=bool)
    Phi, Ga, G2, dPhi, dGa, dG2 = hold_derivatives(A, B, dt, hold, mask)
    which = np.flatnonzero(mask)
    q = which.size
    dPhi, dGa, dG2 = dPhi[which], dGa[which], dG2[which]
    if hold == "zoh":
        E0, E1 = Ga, np.zeros_like(Ga)
        dE0, dE1 = dGa, np.zeros_like(dGa)
    else:
        E0, E1 = Ga - G2, G2
        dE0, dE1 = dGa - dG2, dG2
    # Φ^i and its derivative, i = 0 … s.
    powers = [np.eye(n)]
    dpowers = [np.zeros((q, n, n))]
    for _ in range(s):
        dpowers.append(dpowers[-1] @ Phi + powers[-1] @ dPhi)
        powers.append(powers[-1] @ Phi)
    pe0 = [p @ E0 for p in powers]
    pe1 = [p @ E1 for p in powers]
    dpe0 = [dp @ E0 + p @ dE0 for p, dp in zip(powers, dpowers, strict=True)]
    dpe1 = [dp @ E1 + p @ dE1 for p, dp in zip(powers, dpowers, strict=True)]

    def coefficient(i: int, l: int) -> tuple[np.ndarray, np.ndarray]:
        """T_il and its derivative."""
        value, change = np.zeros((n, r)), np.zeros((q, n, r))
        if l < i:
            value, change = value + pe0[i - 1 - l], change + dpe0[i - 1 - l]
        if 1 <= l <= i:
            value, change = value + pe1[i - l], change + dpe1[i - l]
        return value, change

    Bb, dBb = np.zeros((n, s + 1, r)), np.zeros((q, n, s + 1, r))
    W, dW = np.zeros((n, s + 1, r)), np.zeros((q, n, s + 1, r))
    for l in range(s + 1):
        Bb[:, l], dBb[:, :, l] = coefficient(s, l)
        for i in range(s):
            value, change = coefficient(i, l)
            W[:, l] += value / s
            dW[:, :, l] += change / s
    M = sum(powers[:s]) / s
    dM = sum(dpowers[:s]) / s
    L = np.hstack([np.tile(np.eye(r), s) / s, np.zeros((r, r))])
    W = W.reshape(n, -1)
    rd = (s + 1) * r
    lifted = StateSpace(powers[s], Bb.reshape(n, rd), C @ M, C @ W + D @ L)
    if not jacobian:
        return lifted, None
    rows = n * n + n * rd + m * n + m * rd
    chain = np.zeros((rows, k + m * n + m * r))
    kb = n * n + n * rd
    chain[: n * n, which] = dpowers[s].reshape(q, -1).T
    chain[n * n : kb, which] = dBb.reshape(q, -1).T
    chain[kb : kb + m * n, which] = (C @ dM).reshape(q, -1).T
    chain[kb + m * n :, which] = (C @ dW.reshape(q, n, rd)).reshape(q, -1).T
    # C enters through C M and C W, D through D L (row-major: vec(C X) = (I ⊗ Xᵀ) vec C).
    chain[kb : kb + m * n, k : k + m * n] = np.kron(np.eye(m), M.T)
    chain[kb + m * n :, k : k + m * n] = np.kron(np.eye(m), W.T)
    chain[kb + m * n :, k + m * n :] = np.kron(np.eye(m), L.T)
    return lifted, chain
