"""Observer/Kalman filter identification (OKID): observer and system Markov parameters.

Sources: Juang, Phan, Horta & Longman, "Identification of observer/Kalman filter Markov
parameters: theory and experiments", J. Guidance, Control, and Dynamics 16(2), 1993;
Juang, *Applied System Identification*, Prentice Hall 1994, ch. 6; thesis eq. 4.8–4.19.

With an observer gain G the discrete system (A, B, C, D) becomes (eq. 4.8–4.9)

    x(k+1) = Ā x(k) + B̄ v(k),   Ā = A + G C,   B̄ = [B + G D, −G],   v(k) = [u(k); y(k)]

and, for p with Ā^p ≈ 0 (a deadbeat observer exists whenever p·m ≥ n), every output is a
linear function of the p previous inputs and outputs (eq. 4.10–4.11):

    y(k) = D u(k) + Σ_{i=1..p} Ȳ_i v(k−i),   Ȳ_i = C Ā^{i−1} B̄ = [Ȳ_i⁽¹⁾, −Ȳ_i⁽²⁾].

The Ȳ_i (observer Markov parameters) are found by linear least squares; the system Markov
parameters Y_k = C A^{k−1} B follow by the recursion of eq. 4.14.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from agent.ident.errors import DataError, IdentificationFailed, InsufficientDataError

if TYPE_CHECKING:
    from agent.ident.aircraft.airangles import Synthesised

# Rows per unknown in each output's regression: below two the fit is barely determined and
# the Markov parameters are mostly noise.
MIN_ROWS_PER_UNKNOWN = 2
# Relative singular-value cut-off of the (column-normalised) regression when no Tikhonov
# weight is given: noise-free records with p above the deadbeat order are exactly rank
# deficient, and the minimum-norm solution is the one that keeps the recursion well behaved.
# 1e-10 rather than machine precision: a noise-free record with p above the deadbeat order
# has near-null directions (a weak input such as throttle) at 1e-11…1e-13 that otherwise enter
# the solution and are amplified by the Markov recursion (measured: eigenvalue error 3e-4 at
# 1e-12 against 2e-6 at 1e-10 for the A.3 model with p = 15). Noisy data never gets near it.
RCOND = 1e-10


@dataclass(frozen=True)
class Experiment:
    """One contiguous record: inputs u (l × r) and outputs y (l × m), trim already removed.

    Optional, for the whole-aircraft method (agent.ident.aircraft): `operating_point`, the
    outputs' trim values that were removed (m,), and `navigation`, the INS's heading and
    north, east and down velocities (l × 4, absolute, rad and m/s) that the wind is measured
    from; `air_angles`, where α and β were synthesised from the INS and an estimated wind (no
    vanes: agent.ident.aircraft.airangles), how: the gust's α and β are then not measured;
    `flight`, the absolute time histories (l,) of aircraft states the record measures but the
    model does not output, by role (a lateral run's airspeed and θ): their kinematics."""

    u: np.ndarray
    y: np.ndarray
    operating_point: np.ndarray | None = None
    navigation: np.ndarray | None = None
    air_angles: Synthesised | None = None
    flight: Mapping[str, np.ndarray] | None = None

    @property
    def length(self) -> int:
        return int(self.u.shape[0])


def _optional(exp, index: int, length: int, outputs: int):
    """The experiment's operating point and navigation, checked (None when absent)."""
    op = getattr(exp, "operating_point", None)
    nav = getattr(exp, "navigation", None)
    if op is not None:
        op = np.asarray(op, dtype=float).ravel()
        if op.shape != (outputs,) or not np.isfinite(op).all():
            raise DataError(
                f"experiment {index}: the operating point needs {outputs} finite "
                "values, one per output"
            )
    if nav is not None:
        nav = np.asarray(nav, dtype=float)
        if nav.shape != (length, 4) or not np.isfinite(nav).all():
            raise DataError(
                f"experiment {index}: navigation needs {length} finite rows of "
                "heading, north, east and down velocity"
            )
    return op, nav


def _flight(exp, index: int, length: int) -> dict[str, np.ndarray] | None:
    """The experiment's flight states (`Experiment.flight`), checked (None when absent)."""
    flight = getattr(exp, "flight", None)
    if not flight:
        return None
    out = {}
    for role, values in flight.items():
        values = np.asarray(values, dtype=float).ravel()
        if values.shape != (length,) or not np.isfinite(values).all():
            raise DataError(
                f"experiment {index}: the flight state {role!r} needs {length} finite values"
            )
        out[str(role)] = values
    return out


def as_experiments(experiments: Sequence[Experiment] | Experiment) -> list[Experiment]:
    """Validate a batch of experiments: consistent channel counts, finite values, 2-D arrays."""
    batch = [experiments] if isinstance(experiments, Experiment) else list(experiments)
    if not batch:
        raise DataError("no experiments given")
    clean = []
    for index, exp in enumerate(batch):
        u = np.asarray(exp.u, dtype=float)
        y = np.asarray(exp.y, dtype=float)
        u = u[:, None] if u.ndim == 1 else u
        y = y[:, None] if y.ndim == 1 else y
        if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
            raise DataError(
                f"experiment {index}: inputs {u.shape} and outputs {y.shape} must be 2-D with "
                "the same number of samples"
            )
        if not (np.isfinite(u).all() and np.isfinite(y).all()):
            raise DataError(f"experiment {index}: inputs or outputs contain NaN or infinity")
        op, nav = _optional(exp, index, u.shape[0], y.shape[1])
        air = getattr(exp, "air_angles", None)
        flight = _flight(exp, index, u.shape[0])
        clean.append(
            Experiment(u=u, y=y, operating_point=op, navigation=nav, air_angles=air, flight=flight)
        )
    r, m = clean[0].u.shape[1], clean[0].y.shape[1]
    for index, exp in enumerate(clean):
        if exp.u.shape[1] != r or exp.y.shape[1] != m:
            raise DataError(
                f"experiment {index} has {exp.u.shape[1]} inputs and {exp.y.shape[1]} outputs; "
                f"experiment 0 has {r} and {m}"
            )
    return clean


@dataclass(frozen=True, kw_only=True)
class ObserverMarkov:
    """Observer Markov parameters (eq. 4.12–4.13) and the regression diagnostics."""

    D: np.ndarray  # (m, r); zeros when D is not estimated
    Ybar1: np.ndarray  # (p, m, r): Ȳ_k⁽¹⁾ = C Ā^{k−1}(B + G D)
    Ybar2: np.ndarray  # (p, m, m): Ȳ_k⁽²⁾ = C Ā^{k−1} G
    rows: int  # regression rows used (over all experiments)
    residual_rms: np.ndarray  # (m,) one-step prediction residual per output
    singular_values: np.ndarray  # of the column-normalised regression matrix
    rank: int  # singular values kept

    @property
    def markov(self) -> int:
        return int(self.Ybar1.shape[0])


def regression_columns(r: int, m: int, p: int, estimate_d: bool) -> int:
    """Unknowns per output of the OKID regression: r·[D] + p·(r + m)."""
    return (r if estimate_d else 0) + p * (r + m)


def minimum_length(r: int, m: int, p: int, estimate_d: bool) -> int:
    """Fewest samples a single experiment needs for p Markov parameters."""
    return p + MIN_ROWS_PER_UNKNOWN * regression_columns(r, m, p, estimate_d)


def build_regression(
    experiments: Sequence[Experiment], p: int, estimate_d: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Stack the OKID regression Φ Θ = Y over experiments (eq. 4.11, transposed).

    Row k of an experiment is [u(k) (if D), v(k−1), v(k−2), …, v(k−p)] → y(k) for
    k = p … l−1. Rows never straddle two experiments: each experiment contributes only rows
    whose whole history lies inside it. Every experiment must be longer than p
    (`_check_length`), so none is dropped silently.
    """
    blocks_phi, blocks_y = [], []
    for exp in experiments:
        l = exp.length
        v = np.hstack([exp.u, exp.y])
        cols = [exp.u[p:l]] if estimate_d else []
        cols += [v[p - i : l - i] for i in range(1, p + 1)]
        blocks_phi.append(np.hstack(cols))
        blocks_y.append(exp.y[p:l])
    return np.vstack(blocks_phi), np.vstack(blocks_y)


# Regression rows per block of the streamed least squares (`observer_markov`): the triangle
# of [Φ | Y] is updated block by block, so memory is one block of Φ, not the whole record's
# (a 5-million-row record at p = 30 with six channels would need 7 GB of Φ at once).
REGRESSION_BLOCK = 65_536


def regression_blocks(experiments: Sequence[Experiment], p: int, estimate_d: bool):
    """The rows of `build_regression`, in order, as blocks (Φ_b, Y_b) of at most
    REGRESSION_BLOCK rows."""
    rows = REGRESSION_BLOCK
    for exp in experiments:
        l = exp.length
        for first in range(p, l, rows):
            last = min(first + rows, l)
            v = np.hstack([exp.u[first - p : last], exp.y[first - p : last]])
            cols = [exp.u[first:last]] if estimate_d else []
            cols += [v[p - i : p - i + last - first] for i in range(1, p + 1)]
            yield np.hstack(cols), exp.y[first:last]


def channel_rms(experiments: Sequence[Experiment]) -> tuple[np.ndarray, np.ndarray]:
    """RMS of every input and output channel over the batch (1 where a channel is all zero)."""
    u = np.vstack([e.u for e in experiments])
    y = np.vstack([e.y for e in experiments])
    su = np.sqrt(np.mean(u**2, axis=0))
    sy = np.sqrt(np.mean(y**2, axis=0))
    return np.where(su > 0, su, 1.0), np.where(sy > 0, sy, 1.0)


def _check_length(experiments: Sequence[Experiment], p: int, estimate_d: bool) -> None:
    r, m = experiments[0].u.shape[1], experiments[0].y.shape[1]
    for index, exp in enumerate(experiments):
        if exp.length <= p:
            raise InsufficientDataError(
                f"experiment {index} has {exp.length} samples, too few for {p} Markov "
                "parameters (it would add no regression row); drop it or lower p"
            )
    unknowns = regression_columns(r, m, p, estimate_d)
    rows = sum(e.length - p for e in experiments)
    needed = MIN_ROWS_PER_UNKNOWN * unknowns
    if rows < needed:
        samples = sum(e.length for e in experiments)
        raise InsufficientDataError(
            f"{samples} samples give {rows} regression rows, but {p} Markov parameters with "
            f"{r} inputs and {m} outputs need at least {needed} "
            f"(at least {minimum_length(r, m, p, estimate_d)} samples in one record); "
            "use a longer record or fewer Markov parameters"
        )


def observer_markov(
    experiments: Sequence[Experiment] | Experiment,
    p: int,
    *,
    estimate_d: bool = False,
    regularization: float = 0.0,
) -> ObserverMarkov:
    """Least-squares observer Markov parameters Ȳ_1…Ȳ_p (and D) from a batch of experiments.

    Solves min ‖Φ Θ − Y‖² + λ‖Θ‖² on column-normalised regressors by SVD (never the normal
    equations, which lose positive definiteness in practice for p ≥ 10). λ = (ρ σ_max)² with
    ρ = `regularization`: singular directions weaker than ρ·σ_max are damped (Tikhonov);
    ρ = 0 is plain least squares with a minimum-norm solution for rank-deficient data.
    """
    batch = as_experiments(experiments)
    if p < 1:
        raise DataError(f"the number of Markov parameters must be at least 1, got {p}")
    if regularization < 0:
        raise DataError(f"regularization must be ≥ 0, got {regularization}")
    _check_length(batch, p, estimate_d)
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    su, sy = channel_rms(batch)
    col_scale = np.concatenate(([su] if estimate_d else []) + [np.concatenate([su, sy])] * p)
    # The triangle of [Φ | Y] (column-normalised), streamed: Φ = Q R is never formed whole.
    triangle, rows = None, 0
    for phi, target in regression_blocks(batch, p, estimate_d):
        block = np.hstack([phi / col_scale, target / sy])
        rows += block.shape[0]
        stacked = block if triangle is None else np.vstack([triangle, block])
        if stacked.shape[0] > stacked.shape[1]:
            stacked = scipy.linalg.qr(stacked, mode="r", overwrite_a=True, check_finite=False)[0]
            stacked = stacked[: stacked.shape[1]]
        triangle = stacked
    k = col_scale.size
    theta_s, sv, rank = _tikhonov_solve(triangle[:, :k], triangle[:, k:], regularization)
    theta = theta_s / col_scale[:, None] * sy[None, :]
    if not np.isfinite(theta).all():
        raise IdentificationFailed("the OKID least-squares solution is not finite")
    squares = np.zeros(m)
    for phi, target in regression_blocks(batch, p, estimate_d):
        squares += np.sum((target - phi @ theta) ** 2, axis=0)
    coeffs = theta.T  # (m, columns)
    offset = r if estimate_d else 0
    D = coeffs[:, :r].copy() if estimate_d else np.zeros((m, r))
    blocks = coeffs[:, offset:].reshape(m, p, r + m).transpose(1, 0, 2)
    return ObserverMarkov(
        D=D,
        Ybar1=blocks[:, :, :r].copy(),
        Ybar2=-blocks[:, :, r:].copy(),
        rows=rows,
        residual_rms=np.sqrt(squares / rows),
        singular_values=sv,
        rank=rank,
    )


def _tikhonov_solve(
    phi: np.ndarray, target: np.ndarray, regularization: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Θ = V diag(f) Uᵀ Y with Tikhonov filter factors f = σ/(σ² + λ) (or 1/σ above RCOND).

    A tall Φ is first reduced by the QR factorisation of [Φ | Y] (never forming Q): with
    Φ = Q R and R = U_R Σ Vᵀ, the SVD of Φ is (Q U_R) Σ Vᵀ and Uᵀ Y = U_Rᵀ (Qᵀ Y), the top
    right block of the triangular factor. Same singular values, a fraction of the work.
    """
    k = phi.shape[1]
    if phi.shape[0] > 2 * (k + target.shape[1]):
        triangle = scipy.linalg.qr(np.hstack([phi, target]), mode="r")[0]
        phi, target = triangle[:k, :k], triangle[:k, k:]
    U, sv, Vt = scipy.linalg.svd(phi, full_matrices=False, lapack_driver="gesdd")
    if sv.size == 0 or sv[0] == 0.0:
        raise IdentificationFailed("the OKID regression matrix is all zeros: nothing moved")
    if regularization > 0:
        lam = (regularization * sv[0]) ** 2
        factors = sv / (sv**2 + lam)
        rank = int(np.sum(sv > regularization * sv[0]))
    else:
        keep = sv > RCOND * sv[0]
        factors = np.where(keep, 1.0 / np.where(keep, sv, 1.0), 0.0)
        rank = int(keep.sum())
    return Vt.T @ (factors[:, None] * (U.T @ target)), sv, rank


def system_markov(omp: ObserverMarkov, count: int) -> np.ndarray:
    """System Markov parameters Y_0 = D, Y_k = C A^{k−1} B for k < count (eq. 4.14).

    Y_k = Ȳ_k⁽¹⁾ − Σ_{i=1..min(k,p)} Ȳ_i⁽²⁾ Y_{k−i}, with Ȳ_k⁽¹⁾ = 0 for k > p.
    Returns an array (count, m, r).
    """
    p = omp.markov
    m, r = omp.D.shape
    Y = np.zeros((count, m, r))
    Y[0] = omp.D
    for k in range(1, count):
        acc = omp.Ybar1[k - 1].copy() if k <= p else np.zeros((m, r))
        for i in range(1, min(k, p) + 1):
            acc -= omp.Ybar2[i - 1] @ Y[k - i]
        Y[k] = acc
    return Y


def observer_gain_markov(omp: ObserverMarkov, count: int) -> np.ndarray:
    """Observer-gain Markov parameters Y^o_k = C A^{k−1} G for k = 1…count (eq. 4.18).

    Y^o_k = Ȳ_k⁽²⁾ − Σ_{i=1..min(k−1,p)} Ȳ_i⁽²⁾ Y^o_{k−i}, with Ȳ_k⁽²⁾ = 0 for k > p.
    Returns an array (count, m, m) whose index 0 holds Y^o_1.
    """
    p = omp.markov
    m = omp.D.shape[0]
    Yo = np.zeros((count, m, m))
    for k in range(1, count + 1):
        acc = omp.Ybar2[k - 1].copy() if k <= p else np.zeros((m, m))
        for i in range(1, min(k - 1, p) + 1):
            acc -= omp.Ybar2[i - 1] @ Yo[k - i - 1]
        Yo[k - 1] = acc
    return Yo


def observer_gain(A: np.ndarray, C: np.ndarray, Yo: np.ndarray) -> np.ndarray:
    """Observer gain G = [C; CA; …; CA^{k−1}]† [Y^o_1; …; Y^o_k] (eq. 4.19).

    A + G C is the identified observer of eq. 4.9; for noise-free data and p at the deadbeat
    order its eigenvalues are zero. G is in the state coordinates of the (A, C) given.
    """
    k, m, _ = Yo.shape
    n = A.shape[0]
    blocks, power = [], np.eye(n)
    for _ in range(k):
        blocks.append(C @ power)
        power = power @ A
    obs = np.vstack(blocks)
    return np.linalg.lstsq(obs, Yo.reshape(k * m, m), rcond=None)[0]


def supported_markov(batch: Sequence[Experiment], p_max: int, estimate_d: bool) -> int:
    """Largest p ≤ p_max for which every experiment adds rows and the batch has enough of them.

    0 means not even p = 1.
    """
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    p = min(p_max, min(e.length for e in batch) - 1)
    while p >= 1:
        rows = sum(e.length - p for e in batch)
        if rows >= MIN_ROWS_PER_UNKNOWN * regression_columns(r, m, p, estimate_d):
            return p
        p -= 1
    return 0
