"""Modes of an identified model and their quality indicators (thesis section 5.2).

In modal coordinates (eq. 5.1) Λ = Ψ⁻¹ A Ψ, B_m = Ψ⁻¹ B (rows b_i), C_m = C Ψ (columns c_i).
A complex pair is one mode (reported once, Im s > 0); a real eigenvalue is its own mode and
is never merged with another into a fake pair. A deadbeat pole (z ≈ 0, convert.deadbeat: a
pure sample delay, or a pole too fast for the samples to show) has no continuous-time
eigenvalue and is no mode: it is left out, and `left_out` says so.

Indicators, each in percent (0–100):
- MSV, modal singular value: the norm of the mode's share of the pulse response,
  ‖[c_i b_i, c_i λ_i b_i, …, c_i λ_i^{l−1} b_i]‖ (eq. 5.3–5.4; Juang, *Applied System
  Identification*, §5.8), over the l = α + β − 1 steps the Hankel matrix spans, relative to the
  largest. The finite sum is kept on purpose: the closed form ‖c‖‖b‖/(1 − |λ|) of eq. 5.2 is
  undefined for unstable modes (the thesis's objection to MSV), the finite sum is not.
- MCI / MOI, modal controllability / observability (eq. 5.2): ‖b_i‖ and ‖c_i‖ relative to the
  largest. Eigenvectors are scaled to unit length in the model's internally balanced
  coordinates (the coordinates ERA itself returns), which makes both independent of the state
  coordinates the model happens to be written in.
- EMAC, extended modal amplitude coherence (Pappa, Elliott & Schenk, "Consistent-mode
  indicator for the eigensystem realization algorithm", JGCD 16(5), 1993; eq. 5.8–5.14): the
  mode's last block of the data's Hankel observability factor P_n Σ^{1/2} Ψ is compared with
  its first block extrapolated by λ^{α−1}; per output, amplitude ratio (≤ 1) times the phase
  weight max(0, 1 − |Δφ|/(π/4)); outputs averaged with weights |c_ij|². The same on the
  controllability factor's last block column gives the input EMAC; EMAC = output × input.
- MPC, modal phase collinearity (eq. 5.15–5.18): ((λ₁ − λ₂)/(λ₁ + λ₂))² of the 2 × 2 matrix
  [Re c, Im c]ᵀ[Re c, Im c]. We use the *uncentred* variant: Pappa et al. subtract the mean of
  the real and imaginary parts, which suits many like sensors on one structure, but the mean of
  β, p, r and φ is not a physical quantity and with four channels it dominates the result.
  A real mode has MPC = 100.
- CMI, consistent mode indicator (eq. 5.7): EMAC × MPC.

Inputs and outputs are first divided by scales (by default the RMS of the measured
channels), so indicators and mode shapes do not depend on units (rad vs m/s vs degrees).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from agent.ident.convert import DEADBEAT_MODULUS, continuous_eigenvalues, deadbeat
from agent.ident.errors import IdentificationFailed

# An eigenvalue with |Im z| below this fraction of |z| is real.
REAL_TOLERANCE = 1e-10
# Eigenvector matrices worse conditioned than this mean a defective A (no modal basis).
MAX_EIGENVECTOR_COND = 1e12
# The largest log of a pole's growth over the modal analysis's horizon: beyond it its powers
# overflow (float64 ends near e⁷⁰⁹), so a model with such a pole (a diverged fit) gets a clear
# failure, not an SVD that does not converge.
MAX_LOG_GROWTH = 300.0


# Not era.EraResult: its two factors alone, to transform along with a StateSpace.
@dataclass(frozen=True)
class HankelFactors:
    """ERA's data factors P_n Σ^{1/2} (α·m × n) and Σ^{1/2} Q_nᵀ (n × β·r), model coordinates."""

    observability: np.ndarray
    controllability: np.ndarray

    def transformed(self, T: np.ndarray) -> HankelFactors:
        """The factors in coordinates z = T x, to go with `StateSpace.transformed(T)`."""
        return HankelFactors(self.observability @ np.linalg.inv(T), T @ self.controllability)


@dataclass(frozen=True, kw_only=True)
class EigenvalueStd:
    """1-σ uncertainty of one continuous eigenvalue s = ln(z)/Δt and of what it implies."""

    real: float
    imag: float
    frequency: float  # of |s|, rad/s
    damping: float  # of −Re s/|s|


@dataclass(frozen=True, kw_only=True)
class Mode:
    """One mode: a real eigenvalue or a complex pair, with its indicators in percent."""

    eigenvalue: complex  # continuous, 1/s, Im ≥ 0
    discrete: complex  # z = exp(s Δt)
    pair: bool
    frequency: float  # natural frequency |s|, rad/s
    damping: float  # −Re s / |s| (±1 for real modes)
    time_constant: float | None  # −1/s for real modes (negative: divergent), None for pairs
    msv: float
    mci: float
    moi: float
    emac: float | None  # None without Hankel factors
    mpc: float
    cmi: float | None
    shape: np.ndarray  # scaled output mode shape c_i, largest component 1 with zero phase
    name: str | None = None
    uncertainty: EigenvalueStd | None = None  # Cramér–Rao 1-σ, after refinement

    @property
    def stable(self) -> bool:
        return abs(self.discrete) < 1.0


def modal_analysis(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    dt: float,
    *,
    factors: HankelFactors | None = None,
    input_scale: np.ndarray | None = None,
    output_scale: np.ndarray | None = None,
    horizon: tuple[int, int] = (20, 20),
    balance: bool = True,
) -> list[Mode]:
    """Modes of the discrete model (A, B, C) sorted by natural frequency, with indicators;
    its deadbeat poles (z ≈ 0) are no modes and are left out (`left_out` says why).

    `horizon` (α, β) is the Hankel span for balancing and MSV; with `factors` it is taken
    from their shapes. Without `factors`, EMAC and CMI are None. `balance=False` skips the
    balanced eigenvector lengths: MSV, EMAC and MPC do not depend on them (they are
    invariant to each eigenvector's scale), MCI and MOI do and are then in the model's
    coordinates — for a quick screen of modes, not for a report.
    """
    m, r = C.shape[0], B.shape[1]
    su = np.ones(r) if input_scale is None else np.asarray(input_scale, dtype=float)
    sy = np.ones(m) if output_scale is None else np.asarray(output_scale, dtype=float)
    Bs, Cs = B * su, C / sy[:, None]
    if factors is not None:
        horizon = (factors.observability.shape[0] // m, factors.controllability.shape[1] // r)
    z, Psi = scipy.linalg.eig(A)
    steps = sum(horizon)
    with np.errstate(divide="ignore"):
        growth = np.log(np.maximum(np.abs(z), 1e-300))
    if np.max(growth) * steps > MAX_LOG_GROWTH:
        worst = z[int(np.argmax(growth))]
        raise IdentificationFailed(
            f"the identified model has a pole of {np.log(abs(worst)) / dt:.3g} 1/s (its "
            f"response grows {abs(worst):.3g}× per sample, beyond what {steps} samples of "
            "modal analysis can hold): the fit diverged; a response that does not stand "
            "above the noise or the turbulence does that — excite harder or in calmer air"
        )
    if np.linalg.cond(Psi) > MAX_EIGENVECTOR_COND:
        raise IdentificationFailed(
            "the identified A is defective (repeated eigenvalues without a full set of "
            "eigenvectors), so it has no modal decomposition; try another order"
        )
    if balance:
        Psi = Psi / _balanced_norms(A, Bs, Cs, Psi, horizon)
    Psi_inv = np.linalg.inv(Psi)
    Bm, Cm = Psi_inv @ Bs, Cs @ Psi
    delays = deadbeat(z)
    keep = [i for i in range(z.size) if z[i].imag >= -REAL_TOLERANCE * abs(z[i]) and not delays[i]]
    if not keep:
        return []
    msv = _pulse_norms(z[keep], Bm[keep], Cm[:, keep], sum(horizon) - 1)
    bnorm = np.linalg.norm(Bm[keep], axis=1)
    cnorm = np.linalg.norm(Cm[:, keep], axis=0)
    mpcs = modal_phase_collinearity(Cm[:, keep])
    emac = None
    if factors is not None:
        Pm = (factors.observability / np.tile(sy, horizon[0])[:, None]) @ Psi[:, keep]
        Qm = Psi_inv[keep] @ (factors.controllability * np.tile(su, horizon[1])[None, :])
        emac = _emac(z[keep], Pm, Qm, m, r)
    modes = []
    for j, i in enumerate(keep):
        s = complex(continuous_eigenvalues(z[i], dt))
        pair = abs(z[i].imag) > REAL_TOLERANCE * abs(z[i])
        mpc = float(mpcs[j])
        e = None if emac is None else 100.0 * float(emac[j])
        modes.append(
            Mode(
                eigenvalue=s,
                discrete=complex(z[i]),
                pair=pair,
                frequency=abs(s),
                damping=-s.real / abs(s) if abs(s) > 0 else 1.0,
                time_constant=None if pair or s.real == 0 else -1.0 / s.real,
                msv=100.0 * float(msv[j] / msv.max()) if msv.max() > 0 else 0.0,
                mci=100.0 * float(bnorm[j] / bnorm.max()) if bnorm.max() > 0 else 0.0,
                moi=100.0 * float(cnorm[j] / cnorm.max()) if cnorm.max() > 0 else 0.0,
                emac=e,
                mpc=100.0 * mpc,
                cmi=None if e is None else e * mpc,
                shape=_normalised_shape(Cm[:, i]),
            )
        )
    return sorted(modes, key=lambda mode: (mode.frequency, mode.eigenvalue.imag))


@dataclass(frozen=True)
class SecondOrder:
    """A named mode made of two real poles as the one second-order mode it is: ωn and ζ of its
    polynomial (s − s1)(s − s2), and their Cramér–Rao 1-σ where the model's covariance is
    known (agent.ident.refine.second_order_std)."""

    name: str
    frequency: float
    damping: float
    poles: tuple[float, float]
    frequency_std: float | None = None
    damping_std: float | None = None


def second_order(modes: Sequence[Mode]) -> list[SecondOrder]:
    """Each named mode made of two real poles (an overdamped short period or phugoid) as the
    one second-order mode it is. Near ζ = 1 its ωn and ζ are well determined where the two
    poles are not (a 1 % change of the polynomial moves them apart or into a complex pair)."""
    out = []
    for name in dict.fromkeys(m.name for m in modes if m.name):
        mine = [m for m in modes if m.name == name]
        if len(mine) != 2 or any(m.pair for m in mine):
            continue
        s1, s2 = (m.eigenvalue.real for m in mine)
        if s1 * s2 <= 0:
            continue
        wn = float(np.sqrt(s1 * s2))
        out.append(SecondOrder(name, wn, float(-(s1 + s2) / (2 * wn)), (s1, s2)))
    return out


def left_out(A: np.ndarray, dt: float, Ac: np.ndarray | None = None) -> list[str]:
    """Why each pole of the discrete A that `modal_analysis` leaves out (z ≈ 0) is no mode,
    one line each; `Ac`, the continuous model A is the sampling of, names the pole it was."""
    z = np.linalg.eigvals(A)
    delays = sorted(z[deadbeat(z)], key=abs)
    if not delays:
        return []
    fastest = (
        [None] * len(delays) if Ac is None else sorted(np.linalg.eigvals(Ac), key=lambda s: s.real)
    )
    lines = []
    for zi, s in zip(delays, fastest, strict=False):
        pole = "" if s is None else f"; {_pole(s)} in the continuous model"
        lines.append(
            f"a pole at z ≈ 0 (|z| = {abs(zi):.1e} < {DEADBEAT_MODULUS:.1e}{pole}): a pure "
            f"sample delay, or a pole too fast for samples {dt:g} s apart, with no "
            "continuous-time eigenvalue: left out of the modes"
        )
    return lines


def _pole(s: complex) -> str:
    return f"{s.real:.4g} 1/s" if s.imag == 0 else f"{s.real:.4g} ± {abs(s.imag):.4g}j 1/s"


def _balanced_norms(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, Psi: np.ndarray, horizon: tuple[int, int]
) -> np.ndarray:
    """Length of each eigenvector in the internally balanced coordinates over the horizon.

    With O and R the α-step observability and β-step controllability matrices and
    O R = U Σ Vᵀ, the balanced state is x_b = Σ^{−1/2} Uᵀ O x (so O T = U Σ^{1/2}).
    For a non-minimal model (Σ has zeros) there is no balanced form: lengths in the given
    coordinates are used instead.
    """
    n = A.shape[0]
    alpha, beta = horizon
    powers = [np.eye(n)]
    for _ in range(max(alpha, beta) - 1):
        powers.append(powers[-1] @ A)
    O = np.vstack([C @ P for P in powers[:alpha]])
    R = np.hstack([P @ B for P in powers[:beta]])
    U, sv, _ = np.linalg.svd(O @ R, full_matrices=False)
    if sv.size < n or sv[n - 1] <= 1e-12 * sv[0]:
        return np.linalg.norm(Psi, axis=0)
    to_balanced = (U[:, :n] / np.sqrt(sv[:n])).T @ O
    return np.linalg.norm(to_balanced @ Psi, axis=0)


def _pulse_norms(z: np.ndarray, Bm: np.ndarray, Cm: np.ndarray, steps: int) -> np.ndarray:
    """Frobenius norm of each mode's real pulse-response share over `steps` samples.

    z (k,), Bm (k × r) rows and Cm (m × k) columns of the kept modes; a complex mode stands
    for its pair, so its share is twice the real part.
    """
    powers = z[None, :] ** np.arange(steps)[:, None]  # (steps × k)
    block = np.einsum("tk,ik,kj->tijk", powers, Cm, Bm).real
    pair = np.abs(z.imag) > REAL_TOLERANCE * np.abs(z)
    return np.sqrt(np.sum(block**2, axis=(0, 1, 2))) * np.where(pair, 2.0, 1.0)


def _coherence(first: np.ndarray, last: np.ndarray, z_power: np.ndarray) -> np.ndarray:
    """Weighted amplitude-and-phase agreement of `last` with `first`·z_power (Pappa 1993).

    Columns are modes: first, last (len × k), z_power (k,); one value per mode.
    """
    predicted = first * z_power[None, :]
    weights = np.abs(first) ** 2
    a, p = np.abs(last), np.abs(predicted)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((a > 0) & (p > 0), np.minimum(a, p) / np.maximum(a, p), 0.0)
        phase = np.angle(np.where(p > 0, last / np.where(p > 0, predicted, 1.0), 0.0))
    weight = np.maximum(0.0, 1.0 - np.abs(phase) / (np.pi / 4))
    total = weights.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, np.sum(ratio * weight * weights, axis=0) / total, 0.0)


def _emac(z: np.ndarray, Pm: np.ndarray, Qm: np.ndarray, m: int, r: int) -> np.ndarray:
    """Output EMAC × input EMAC of each mode from its columns (rows) of the Hankel factors."""
    alpha, beta = Pm.shape[0] // m, Qm.shape[1] // r
    out = _coherence(Pm[:m], Pm[(alpha - 1) * m :], z ** (alpha - 1))
    inp = _coherence(Qm[:, :r].T, Qm[:, (beta - 1) * r :].T, z ** (beta - 1))
    return out * inp


def modal_phase_collinearity(Cm: np.ndarray) -> np.ndarray:
    """Uncentred modal phase collinearity ((λ₁ − λ₂)/(λ₁ + λ₂))² of each shape column (eq.
    5.15–5.18), λ the eigenvalues of XᵀX with X = [Re c, Im c]."""
    a = np.sum(Cm.real**2, axis=0)
    d = np.sum(Cm.imag**2, axis=0)
    b = np.sum(Cm.real * Cm.imag, axis=0)
    total = a + d
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, (4 * (((a - d) / 2) ** 2 + b**2)) / total**2, 0.0)


def _normalised_shape(c: np.ndarray) -> np.ndarray:
    """c scaled so its largest component is 1 with zero phase."""
    k = int(np.argmax(np.abs(c)))
    return c / c[k] if abs(c[k]) > 0 else c.astype(complex)


def modal_subspace(A: np.ndarray, keep: Sequence[complex]) -> tuple[np.ndarray, np.ndarray]:
    """Real bases (V: n × k, W: k × n, W V = I) of the invariant subspace of the kept modes.

    `keep` lists discrete eigenvalues (one per complex pair); each pair contributes the real
    and imaginary parts of its eigenvector, so W A V, W B, C V is a real model holding those
    modes exactly (modal truncation).
    """
    z, vecs = scipy.linalg.eig(A)
    used = np.zeros(z.size, dtype=bool)
    chosen = set()
    for target in keep:
        k = int(np.argmin(np.where(used, np.inf, np.abs(z - target))))
        chosen.add(k)
        used[k] = True
    order_real, kept = [], []
    done = np.zeros(z.size, dtype=bool)
    for k in range(z.size):
        if done[k]:
            continue
        pair = abs(z[k].imag) > REAL_TOLERANCE * abs(z[k])
        partner = None
        if pair:
            rest = np.where(done, np.inf, np.abs(z - z[k].conj()))
            rest[k] = np.inf
            partner = int(np.argmin(rest))
            done[partner] = True
            order_real.extend([vecs[:, k].real, vecs[:, k].imag])
            kept.extend([k in chosen or partner in chosen] * 2)
        else:
            order_real.append(vecs[:, k].real)
            kept.append(k in chosen)
        done[k] = True
    T = np.column_stack(order_real)
    Tinv = np.linalg.inv(T)
    mask = np.array(kept)
    return T[:, mask], Tinv[mask]
