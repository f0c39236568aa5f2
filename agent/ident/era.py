"""Eigensystem Realization Algorithm (ERA): a minimal state-space model from Markov parameters.

Sources: Juang & Pappa, "An eigensystem realization algorithm for modal parameter
identification and model reduction", J. Guidance, Control, and Dynamics 8(5), 1985;
thesis eq. 4.15–4.16.

With the block Hankel matrices of the system Markov parameters Y_k = C A^{k−1} B

    H(k−1) = [Y_{k+i+j}]_{i<α, j<β},   H(0) = P Σ Qᵀ,

the order-n realisation is (eq. 4.16)

    A = Σ_n^{−1/2} P_nᵀ H(1) Q_n Σ_n^{−1/2},   B = first r columns of Σ_n^{1/2} Q_nᵀ,
    C = first m rows of P_n Σ_n^{1/2},          D = Y_0.

The realisation is internally balanced over the Hankel span: its observability and
controllability factors P_n Σ_n^{1/2} and Σ_n^{1/2} Q_nᵀ, kept here for the consistency
indicators (EMAC), have equal Gramians Σ_n.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from agent.ident.errors import DataError, IdentificationFailed

# Singular values below this fraction of the largest are numerical zeros of the Hankel matrix.
NUMERICAL_ZERO = 1e-13
# Default block rows and columns of the Hankel matrix: 20 samples (0.4 s at 50 Hz) averages
# the Markov parameters over several steps while keeping ERA cheap onboard.
DEFAULT_HANKEL_BLOCKS = 20


@dataclass(frozen=True, kw_only=True)
class EraResult:
    """A discrete realisation (A, B, C, D) with the Hankel diagnostics it came from."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    singular_values: np.ndarray  # every singular value of H(0), descending
    order: int
    rows: int  # α, block rows of the Hankel matrix
    cols: int  # β, block columns
    observability: np.ndarray  # P_n Σ_n^{1/2}, (α·m × n), in the coordinates of A
    controllability: np.ndarray  # Σ_n^{1/2} Q_nᵀ, (n × β·r)


def hankel_matrix(markov: np.ndarray, shift: int, rows: int, cols: int) -> np.ndarray:
    """Block Hankel matrix H(shift) = [Y_{1+shift+i+j}] of size (rows·m × cols·r) (eq. 4.15)."""
    count, m, r = markov.shape
    needed = rows + cols + shift
    if count < needed:
        raise DataError(f"a {rows}×{cols} block Hankel H({shift}) needs {needed} Markov parameters")
    index = 1 + shift + np.arange(rows)[:, None] + np.arange(cols)[None, :]
    return markov[index].transpose(0, 2, 1, 3).reshape(rows * m, cols * r)


def suggest_order(
    singular_values: np.ndarray, max_order: int, structural_rank: int | None = None
) -> int:
    """Model order at the largest relative gap σ_n / σ_{n+1} of the Hankel singular values.

    Only n ≤ max_order are considered, and singular values below NUMERICAL_ZERO·σ_1 are
    treated as that floor, so a noise-free record's rank is found exactly. Markov parameters
    from OKID with p > 1 have at most p·m states (`structural_rank`): with noisy data the
    Hankel rank reaches that bound and the gap into the structural zeros says nothing about
    the aircraft, so it is not a candidate (measured on the A.2 record with sensor noise: that
    gap always won and gave n = p·m).
    """
    sv = np.asarray(singular_values, dtype=float)
    if sv.size == 0 or sv[0] <= 0:
        raise IdentificationFailed("every Hankel singular value is zero: no dynamics in the data")
    rank = int(np.sum(sv > NUMERICAL_ZERO * sv[0]))
    limit = min(max_order, rank, sv.size - 1)
    if structural_rank is not None and rank >= structural_rank and limit == rank and rank > 1:
        limit = rank - 1
    if limit < 1:
        return 1
    floored = np.maximum(sv[: limit + 1], NUMERICAL_ZERO * sv[0])
    gaps = floored[:-1] / floored[1:]
    return int(np.argmax(gaps)) + 1


def default_blocks(m: int, r: int, max_order: int) -> int:
    """Hankel block rows = columns: the default, enlarged until α·min(m, r) covers max_order."""
    return max(DEFAULT_HANKEL_BLOCKS, -(-2 * max_order // min(m, r)))


def era(
    markov: np.ndarray,
    order: int | None = None,
    *,
    rows: int | None = None,
    cols: int | None = None,
    max_order: int = 20,
    structural_rank: int | None = None,
) -> EraResult:
    """Realise (A, B, C, D) from system Markov parameters Y_0…Y_{K−1} (array K × m × r).

    `order` None picks it from the Hankel singular values (`suggest_order`).
    """
    markov = np.asarray(markov, dtype=float)
    _, m, r = markov.shape
    alpha = rows or default_blocks(m, r, max_order)
    beta = cols or alpha
    H0 = hankel_matrix(markov, 0, alpha, beta)
    H1 = hankel_matrix(markov, 1, alpha, beta)
    P, sv, Qt = scipy.linalg.svd(H0, full_matrices=False)
    rank = int(np.sum(sv > NUMERICAL_ZERO * sv[0])) if sv[0] > 0 else 0
    if rank == 0:
        raise IdentificationFailed("every Hankel singular value is zero: no dynamics in the data")
    if order is None:
        n = suggest_order(sv, max_order, structural_rank)
    else:
        n = order
        if n < 1 or n > min(alpha * m, beta * r):
            raise DataError(
                f"order {n} is outside 1…{min(alpha * m, beta * r)} for a "
                f"{alpha}×{beta} block Hankel matrix"
            )
        if n > rank:
            raise IdentificationFailed(
                f"order {n} requested but the Hankel matrix has rank {rank} "
                f"(singular values {_fmt(sv[: rank + 2])}); use order ≤ {rank}"
            )
    Pn, sn, Qn = P[:, :n], sv[:n], Qt[:n].T
    root = np.sqrt(sn)
    obs = Pn * root
    ctrl = (Qn * root).T
    A = (Pn / root).T @ H1 @ (Qn / root)
    return EraResult(
        A=A,
        B=ctrl[:, :r].copy(),
        C=obs[:m].copy(),
        D=markov[0].copy(),
        singular_values=sv,
        order=n,
        rows=alpha,
        cols=beta,
        observability=obs,
        controllability=ctrl,
    )


def _fmt(values: np.ndarray) -> str:
    return ", ".join(f"{v:.3g}" for v in values)
