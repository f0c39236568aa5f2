"""Discrete ↔ continuous time and state coordinates of identified models.

The measured inputs are sampled and held, so the discrete model is the zero-order-hold
equivalent of a continuous one: exp([[Ac, Bc], [0, 0]]·Δt) = [[A, B], [0, I]]. Inverting it
with the principal matrix logarithm (Higham, *Functions of Matrices*, SIAM 2008, ch. 11),

    [[Ac, Bc], [0, 0]] = log([[A, B], [0, I]]) / Δt,

is exact for any A without eigenvalues on the closed negative real axis, including
eigenvalues at 1 (integrators), where the textbook Bc = (A − I)⁻¹ Ac B is singular.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from agent.ident.errors import ContinuousConversionError, DataError

# A discrete eigenvalue whose imaginary part is below this fraction of its modulus, with a
# negative real part, lies on the negative real axis for all practical purposes: its
# logarithm has imaginary part ±π and no real-valued continuous model reproduces it.
NEGATIVE_AXIS_TOLERANCE = 1e-9
# Relative round-trip error ‖expm(logm(M)) − M‖₁/‖M‖₁ above which the logarithm is refused.
LOGM_MAX_ERROR = 1e-6
# C with a condition number above this is not trusted to map states onto outputs.
OUTPUT_COORDINATES_MAX_COND = 1e8
# A discrete eigenvalue this close to 0 is a deadbeat pole: a pure sample delay, with no
# continuous-time eigenvalue. √ε, for two reasons: a pole at 0 of multiplicity two (a delay of
# two samples) is computed up to about √ε from 0 in double precision, so a smaller modulus is
# rounding, and its logarithm a number of the rounding's making; and a pole that small decays
# 10⁸-fold within one sample, so no sampled record shows its rate, only the delay.
DEADBEAT_MODULUS = float(np.sqrt(np.finfo(float).eps))


def discretize(Ac: np.ndarray, Bc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discrete (A, B) of a continuous (Ac, Bc) with step dt."""
    n, r = Bc.shape
    block = np.zeros((n + r, n + r))
    block[:n, :n] = Ac
    block[:n, n:] = Bc
    phi = scipy.linalg.expm(block * dt)
    return phi[:n, :n], phi[:n, n:]


def hold_block(Ac: np.ndarray, Bc: np.ndarray, dt: float) -> np.ndarray:
    """[[Ac, Bc, 0], [0, 0, I/Δt], [0, 0, 0]]·Δt, whose exponential gives the first-order hold.

    With u linear between samples, [x; u; Δu/Δt] obeys these dynamics over one step, so
    expm of this block has top row [Φ, Γa, Γ2] with x(k+1) = Φ x(k) + Γa u(k) + Γ2 Δu(k)
    (Franklin, Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed., §6.3.2).
    """
    n, r = Bc.shape
    M = np.zeros((n + 2 * r, n + 2 * r))
    M[:n, :n] = Ac
    M[:n, n : n + r] = Bc
    M[n : n + r, n + r :] = np.eye(r) / dt
    return M * dt


def hold_derivatives(
    Ac: np.ndarray, Bc: np.ndarray, dt: float, hold: str, moving: np.ndarray | None = None
) -> tuple[np.ndarray, ...]:
    """Φ, Γa, Γ2 of the hold's step (`hold_block`; Γ2 = 0 for "zoh") and their derivatives
    along each entry of [vec Ac, vec Bc] (row-major), (n² + n·r, …) stacked: the derivative of
    expm(M) along dM is the top-right block of expm([[M, dM], [0, M]]), all directions through
    one batched expm, or only those `moving` (a mask over the entries) marks, the others left
    zero."""
    n, r = Bc.shape
    size = n + 2 * r
    M = hold_block(Ac, Bc, dt)
    if hold == "zoh":
        M[:, n + r :] = 0.0  # no ramp input: the top row of expm is then [Φ, Γ, 0]
    E = scipy.linalg.expm(M)
    k = n * n + n * r
    which = np.arange(k) if moving is None else np.flatnonzero(moving)
    big = np.zeros((which.size, 2 * size, 2 * size))
    big[:, :size, :size] = M
    big[:, size:, size:] = M
    in_a = which < n * n
    rows, cols = np.divmod(which[in_a], n)
    big[np.flatnonzero(in_a), rows, size + cols] = dt
    rows, cols = np.divmod(which[~in_a] - n * n, r)
    big[np.flatnonzero(~in_a), rows, size + n + cols] = dt
    dE = np.zeros((k, size, size))
    if which.size:
        dE[which] = scipy.linalg.expm(big)[:, :size, size:]
    return (
        E[:n, :n],
        E[:n, n : n + r],
        E[:n, n + r :],
        dE[:, :n, :n],
        dE[:, :n, n : n + r],
        dE[:, :n, n + r :],
    )


def discretize_hold(
    Ac: np.ndarray, Bc: np.ndarray, C: np.ndarray, D: np.ndarray, dt: float, hold: str
) -> StateSpace:
    """Discrete model with a zero-order ("zoh") or first-order ("foh") hold of the inputs."""
    if hold == "zoh":
        A, B = discretize(Ac, Bc, dt)
        return StateSpace(A, B, C, D)
    if hold == "foh":
        return discretize_foh(Ac, Bc, C, D, dt)
    raise ValueError(f"hold must be 'zoh' or 'foh', not {hold!r}")


def discretize_foh(
    Ac: np.ndarray, Bc: np.ndarray, C: np.ndarray, D: np.ndarray, dt: float
) -> StateSpace:
    """Discrete model of a continuous one whose inputs are linear between samples.

    x(k+1) = Φ x + Γa u(k) + Γ2 (u(k+1) − u(k)) in the state ξ = x − Γ2 u becomes the standard
    ξ(k+1) = Φ ξ + (Φ Γ2 + Γa − Γ2) u(k), y = C ξ + (D + C Γ2) u(k): same eigenvalues as the
    zero-order-hold model, but no half-sample lag for smooth (filtered, servo-driven) inputs.
    """
    n, r = Bc.shape
    E = scipy.linalg.expm(hold_block(Ac, Bc, dt))
    Phi, Ga, G2 = E[:n, :n], E[:n, n : n + r], E[:n, n + r :]
    return StateSpace(Phi, Phi @ G2 + Ga - G2, C, D + C @ G2)


def deadbeat(discrete: np.ndarray) -> np.ndarray:
    """Which discrete eigenvalues are at z = 0 for all the samples show (DEADBEAT_MODULUS)."""
    return np.abs(np.asarray(discrete)) <= DEADBEAT_MODULUS


def continuous_eigenvalues(discrete: np.ndarray, dt: float) -> np.ndarray:
    """s = ln(z)/Δt, principal branch (a negative real z maps to the Nyquist line Im s = π/Δt).

    A deadbeat z (`deadbeat`) has none: ContinuousConversionError; leave such poles out first.
    """
    z = np.asarray(discrete, dtype=complex)
    if np.any(deadbeat(z)):
        raise ContinuousConversionError(
            "a discrete pole at z = 0 (a pure sample delay) has no continuous-time eigenvalue"
        )
    return np.log(z) / dt


def negative_axis_eigenvalues(A: np.ndarray) -> np.ndarray:
    """Eigenvalues of A on the closed negative real axis (zero included)."""
    z = np.linalg.eigvals(A)
    on_axis = (np.abs(z.imag) <= NEGATIVE_AXIS_TOLERANCE * np.abs(z)) & (z.real <= 0)
    return z[on_axis]


def to_continuous(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (Ac, Bc) whose zero-order-hold discretisation at dt is (A, B)."""
    if dt <= 0:
        raise DataError(f"sample time must be positive, got {dt}")
    bad = negative_axis_eigenvalues(A)
    if bad.size:
        delays = int(np.count_nonzero(deadbeat(bad)))
        raise ContinuousConversionError(
            "the discrete model has eigenvalue(s) "
            + ", ".join(f"{z.real:.4g}" for z in bad)
            + " on the negative real axis: no real continuous-time model has them. They are "
            "usually a spurious mode at the Nyquist frequency"
            + (f" ({delays} at z ≈ 0: a pure sample delay)" if delays else "")
            + "; lower the order or the number of Markov parameters"
        )
    n, r = B.shape
    block = np.eye(n + r)
    block[:n, :n] = A
    block[:n, n:] = B
    log = _eigen_log(block)
    if log is None:
        with warnings.catch_warnings():
            # scipy warns on its own error estimate; we check the round trip ourselves below.
            warnings.simplefilter("ignore", RuntimeWarning)
            log = scipy.linalg.logm(block)
    if np.iscomplexobj(log):
        scale = max(np.abs(log).max(), 1.0)
        if np.abs(log.imag).max() > 1e-9 * scale:
            raise ContinuousConversionError("the matrix logarithm of the model is not real")
        log = log.real
    roundtrip = np.linalg.norm(scipy.linalg.expm(log) - block, 1) / np.linalg.norm(block, 1)
    if roundtrip > LOGM_MAX_ERROR:
        raise ContinuousConversionError(
            f"the matrix logarithm is inaccurate (relative round-trip error {roundtrip:.1e}); "
            "the model is too ill-conditioned for a continuous-time equivalent"
        )
    log = log / dt
    return log[:n, :n], log[:n, n:]


# Eigenvector matrices better conditioned than this give the logarithm as V log(Λ) V⁻¹.
EIGEN_LOG_MAX_COND = 1e6


def _eigen_log(M: np.ndarray) -> np.ndarray | None:
    """log(M) = V log(Λ) V⁻¹ for a well-conditioned diagonalisable M (else None).

    A hundred times cheaper than the Schur–Padé logm for the small blocks here; a defective
    or nearly defective block (an integrator meets the input's eigenvalues at 1) falls back.
    """
    values, vectors = np.linalg.eig(M)
    if np.linalg.cond(vectors) > EIGEN_LOG_MAX_COND:
        return None
    log = (vectors * np.log(values.astype(complex))) @ np.linalg.inv(vectors)
    return log


@dataclass(frozen=True)
class StateSpace:
    """A state-space model (discrete or continuous, as the caller says)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    def transformed(self, T: np.ndarray) -> StateSpace:
        """The same system in coordinates z = T x: (T A T⁻¹, T B, C T⁻¹, D)."""
        Tinv = np.linalg.inv(T)
        return StateSpace(T @ self.A @ Tinv, T @ self.B, self.C @ Tinv, self.D)


def output_coordinates_transform(C: np.ndarray) -> np.ndarray | None:
    """T = C when every state is measured (m = n, C well conditioned), else None.

    In coordinates z = C x the states are the measured outputs and A, B read like the
    thesis's appendix A models.
    """
    m, n = C.shape
    if m != n or np.linalg.cond(C) > OUTPUT_COORDINATES_MAX_COND:
        return None
    return C.copy()
