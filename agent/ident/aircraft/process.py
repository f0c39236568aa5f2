"""Unmeasured turbulence as process noise: the frequency-domain filter-error method.

Where the gust is not measured (no INS, or no vanes) it drives the aircraft as noise of its
own: with the vanes' air-relative V and α, ẋ = A x + B u − s g, the gust's rate entering the
V and α equations and, through Dryden's pitch-rate gust, q's. Output error stays consistent
(that noise is independent of the inputs) but weights each output's residual by its own
level; the residual of V, α, q and θ is one gust seen through the aircraft, coherent across
them. The filter-error method (Jategaonkar, *Flight Vehicle System Identification*, 2nd ed.,
2015, ch. 5; Maine & Iliff, NASA RP-1138, ch. 7) models it: each bin's residual e_k = Y_k −
X_k(θ) is complex Gaussian with the spectral matrix

    S_k = T_k Q_k T_kᴴ + R,    T_k = (s_k I − A)⁻¹ E,

Q_k the process noise's spectra on the rows E (diagonal, each smoothed over the fit's
neighbouring bins, as a gust's spectrum is smooth) and R the sensors' white noise (one level
per output over the band: white noise is white). The fit minimises the Whittle likelihood

    J(θ) = Σ_k e_kᴴ S_k(θ)⁻¹ e_k + log det S_k(θ)

at fixed Q and R (S depends on θ through T), and re-estimates Q and R from the residuals
between passes (the relaxation of Jategaonkar §5.6). The log-determinant is not a
constant here: the process noise in bin k is correlated with the state in the same bin,
E[w_k x_kᴴ] = Q (s_k I − A)⁻ᴴ, which biases the fit towards slower modes without it (as
equation error in the frequency domain is biased by process noise). Between Q → 0 (output
error) and R → 0 (equation error) the data choose.

The Gauss–Newton step uses the joint form: e_kᴴ S_k⁻¹ e_k = min over w_k of
|R^(−1/2)(e_k − T_k w_k)|² + |Q_k^(−1/2) w_k|² (the matrix inversion lemma), whose minimiser
ŵ_k = Q_k T_kᴴ S_k⁻¹ e_k is the process noise's conditional mean; eliminating the step in w
leaves the step in θ with the weight S_k⁻¹ and the Jacobian of the response forced by ŵ too
(the gradient is exact by the envelope theorem).

Q and R (`estimate`): Fisher scoring of the same likelihood at fixed θ, the scores of Q
summed over each bin's neighbourhood (the fit's SMOOTH_BINS a side) and those of R over all bins;
both held non-negative.

Without vanes (α synthesised from the INS, the inertial α) the gust forces the state the
same way but the output does not see it: y = x + e g, and T's column for it is
s Φ e − e (`ProcessNoise.direct`), the part through the states being the one that depends
on θ.

Used (agent.ident.aircraft.model) wherever nothing measures α's gust: the vanes alone, or
no vanes. Only the longitudinal axis (`fit.fit_axis`): on JSBSim's aircraft the lateral axis's
process-noise model moved the roll mode away from the truth on every variant tried
(benchmarks/README.md, *The whole-aircraft method's terms*), where its output error holds it;
the lateral axis's process noise (the rolling gust) is modelled in the time domain instead
(agent.ident.aircraft.predictor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Fisher-scoring steps for Q and R at fixed parameters.
STEPS = 15
# R's floor, as a share of the output's residual level: the sensors' noise is never nought.
R_FLOOR = 1e-6
# Eigenvalues of S below this share of its largest count as this share (whitening).
EIGEN_FLOOR = 1e-12


@dataclass(frozen=True)
class ProcessNoise:
    """The residual's spectral model: process noise Q (F, m) on the states `rows` (positions
    among the axis's states) and white sensor noise R (n,), at the fit's bins s (F,).
    `direct`: the rows whose noise is the gust of an air angle synthesised from the INS (no
    vanes), which the state feels and its output does not see (`transfer`)."""

    rows: tuple[int, ...]
    Q: np.ndarray
    R: np.ndarray
    s: np.ndarray
    direct: tuple[int, ...] = ()

    def gain(self, s: np.ndarray) -> np.ndarray:
        """(F, m): what forces each row per unit of its noise (`transfer`)."""
        return _gain(self.rows, self.direct, s)

    def spectrum(self, s: np.ndarray, A: np.ndarray):
        """S (F, n, n), T (F, n, m), T's part through the states and Φ = (sI − A)⁻¹ (F, n, n)
        at the model A."""
        n = A.shape[0]
        phi = np.linalg.inv(s[:, None, None] * np.eye(n) - A)
        T, through = transfer(self.rows, self.direct, s, phi)
        S = np.einsum("fia,fa,fja->fij", T, self.Q, T.conj()) + np.diag(self.R)
        return 0.5 * (S + S.conj().transpose(0, 2, 1)), T, through, phi

    def share(self, A: np.ndarray) -> np.ndarray:
        """Per output, the share of its residual's power (over the bins) the process noise
        explains."""
        S, T, _, _ = self.spectrum(self.s, A)
        process = np.einsum("fia,fa,fia->i", T, self.Q, T.conj()).real
        return process / np.maximum(np.einsum("fii->i", S).real, 1e-300)


def _gain(rows: tuple[int, ...], direct: tuple[int, ...], s: np.ndarray) -> np.ndarray:
    """(F, m): s for a `direct` row (the gust's rate forces it), 1 for the others."""
    return np.stack([s if r in direct else np.ones_like(s) for r in rows], axis=1)


def transfer(rows: tuple[int, ...], direct: tuple[int, ...], s: np.ndarray, phi: np.ndarray):
    """T (F, n, m), the noise on `rows` to the outputs, and its part through the states Φ E
    (the rest does not depend on the model). A synthesised air angle's output (a `direct`
    row) is the inertial one, the air-relative state less the gust: with the state forced by
    the gust's rate, ẋ = A x + B u − s e g and y = x + e g, so T = −(s Φ e − e); the sign of a
    column is immaterial to S."""
    through = phi[:, :, list(rows)] * _gain(rows, direct, s)[:, None, :]
    T = through.copy()
    for a, r in enumerate(rows):
        if r in direct:
            T[:, r, a] -= 1.0
    return T, through


def whiten(S: np.ndarray):
    """W with W S Wᴴ = I, S⁻¹ and log det S, per bin."""
    w, V = np.linalg.eigh(S)
    w = np.maximum(w, EIGEN_FLOOR * np.maximum(w.max(axis=1, keepdims=True), 1e-300))
    W = (V / np.sqrt(w)[:, None, :]).conj().transpose(0, 2, 1)
    inverse = (V / w[:, None, :]) @ V.conj().transpose(0, 2, 1)
    return W, inverse, float(np.sum(np.log(w)))


def estimate(
    problem, theta: np.ndarray, rows: tuple[int, ...], smooth, direct: tuple[int, ...] = ()
) -> ProcessNoise:
    """Q and R from the residuals at `theta` (module docstring): Fisher scoring from the
    output-error weights (Q = 0, R each output's mean residual power). `smooth`: the fit's
    average over neighbouring bins (`fit.smooth_bins`); `direct` as ProcessNoise's."""
    A = problem.unpack(theta)[0]
    X, _ = problem.response(theta)
    e = problem.Y - X
    s, n, m = problem.s, problem.n, len(rows)
    F = s.size
    level = np.mean(np.abs(e) ** 2, axis=0)
    T, _ = transfer(tuple(rows), tuple(direct), s, np.linalg.inv(s[:, None, None] * np.eye(n) - A))
    Z = np.concatenate([T, np.broadcast_to(np.eye(n), (F, n, n))], axis=2)  # (F, n, m + n)
    Q, R = np.zeros((F, m)), level.copy()
    if not np.all(np.isfinite(T)):
        raise np.linalg.LinAlgError("the model has a pole on the frequency axis")
    best, kept = np.inf, (Q, R)
    for step in range(STEPS + 1):
        S = np.einsum("fia,fa,fja->fij", T, Q, T.conj()) + np.diag(R)
        W, P, logdet = whiten(0.5 * (S + S.conj().transpose(0, 2, 1)))
        # Scoring has no line search: keep the spectra of the best likelihood met (the start,
        # white sensor noise, among them), never a step that left it.
        value = float(np.sum(np.abs(np.einsum("fij,fj->fi", W, e)) ** 2)) + logdet
        if value < best:
            best, kept = value, (Q, R)
        if step == STEPS:
            break
        PZ = P @ Z
        M = np.abs(Z.conj().transpose(0, 2, 1) @ PZ) ** 2  # (F, p, p): tr(P D_a P D_b)
        v = np.abs(np.einsum("fia,fi->fa", PZ.conj(), e)) ** 2  # tr(P D_a P e eᴴ)
        # Q: each bin's neighbourhood, R held.
        vq = v[:, :m] - M[:, :m, m:] @ R
        Mq, _ = smooth(M[:, :m, :m].reshape(F, -1), s)
        vq, _ = smooth(vq, s)
        Q = np.maximum(_solve(Mq.reshape(F, m, m), vq), 0.0)
        # R: all bins, Q held.
        vr = (v[:, m:] - np.einsum("fab,fb->fa", M[:, m:, :m], Q)).sum(axis=0)
        R = _solve(M[:, m:, m:].sum(axis=0)[None], vr[None])[0]
        R = np.maximum(R, R_FLOOR * level)
        if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(R))):
            raise np.linalg.LinAlgError("the process-noise spectra did not converge")
    Q, R = kept
    return ProcessNoise(tuple(rows), Q, R, s, tuple(direct))


def significant(problem, theta: np.ndarray, noise: ProcessNoise, width: int) -> bool:
    """Whether the record shows process noise: the likelihood ratio of `noise` against white
    sensor noise alone (Q = 0, R each output's mean residual power) above twice the process
    noise's degrees of freedom (Akaike's criterion; m spectra, each a free value per `width`
    bins). Without process noise the filter-error fit spends the record on estimating a Q
    that is nought and loses efficiency (the thesis's aircraft with white noise: the
    phugoid's scatter 1.6 times its Cramér–Rao bound, where output error holds 1.0–1.3)."""
    X, _ = problem.response(theta)
    white = problem.s.size * float(np.sum(1.0 + np.log(np.mean(np.abs(problem.Y - X) ** 2, 0))))
    ratio = white - cost(problem, theta, noise)
    return ratio > 2.0 * len(noise.rows) * problem.s.size / width


def _solve(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Batched M x = v (M: (F, p, p) symmetric non-negative), scaled by its diagonal and
    lightly regularised (a row of noise no bin sees is left at nought)."""
    d = np.sqrt(np.maximum(np.einsum("fii->fi", M), 1e-300))
    scaled = M / (d[:, :, None] * d[:, None, :]) + 1e-8 * np.eye(M.shape[1])
    return np.linalg.solve(scaled, (v / d)[:, :, None])[:, :, 0] / d


def cost(problem, theta: np.ndarray, noise: ProcessNoise) -> float:
    """J(θ) at fixed Q and R (module docstring); inf where the model has no response."""
    return evaluate(problem, theta, noise)[0]


def evaluate(problem, theta: np.ndarray, noise: ProcessNoise):
    """J(θ) and what `linearised` needs of it at θ (None where J is inf), so that an accepted
    step's evaluation is not done twice."""
    X, _ = problem.response(theta)
    if not np.all(np.isfinite(X)):
        return np.inf, None
    A = problem.unpack(theta)[0]
    S, T, through, phi = noise.spectrum(problem.s, A)
    if not np.all(np.isfinite(S)):
        return np.inf, None
    W, inverse, logdet = whiten(S)
    e = problem.Y - X
    value = float(np.sum(np.abs(np.einsum("fij,fj->fi", W, e)) ** 2)) + logdet
    return value, (e, T, through, phi, W, inverse)


def linearised(problem, theta: np.ndarray, noise: ProcessNoise, state=None):
    """The whitened residual (F, n) and Jacobian of the response (F, n, P; the response forced
    by ŵ too), and the log-determinant's gradient (P,; A's entries only). `state`: `evaluate`'s
    at the same θ, or None."""
    A = problem.unpack(theta)[0]
    if state is None:
        _, state = evaluate(problem, theta, noise)
    e, T, through, phi, W, inverse = state
    what = noise.Q * np.einsum("fia,fi->fa", T.conj(), np.einsum("fij,fj->fi", inverse, e))
    forcing = np.zeros_like(e)
    forcing[:, list(noise.rows)] = what * noise.gain(problem.s)
    known = problem.K
    problem.K = known + forcing
    try:
        _, J = problem.response(theta, jacobian=True)
    finally:
        problem.K = known
    # ∂ log det S_k / ∂A_ij = 2 Re (Φ E Q Tᴴ S⁻¹ Φ)_ji, Φ E the part of T through the states
    process = np.einsum("fia,fa,fja->fij", through, noise.Q, T.conj())
    n = A.shape[0]
    gradient = np.zeros(theta.size)
    gradient[: n * n] = (2 * np.sum(process @ inverse @ phi, axis=0).real.T).ravel()
    return np.einsum("fij,fj->fi", W, e), np.einsum("fij,fjp->fip", W, J), gradient
