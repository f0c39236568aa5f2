"""Whole-aircraft identification in the frequency domain: decoupled longitudinal and lateral
state-space models, each state measured, from one simultaneous maneuver.

Why not OKID/ERA for the full aircraft: eight outputs, four inputs, an engine that lags the
throttle, and slow modes (phugoid, spiral) barely covered by a minute of data give ERA a
Hankel matrix with no clear order and OKID a regression with hundreds of unknowns. A flight-
test engineer knows the structure instead (Klein & Morelli, *Aircraft System Identification*,
AIAA 2006, ch. 7 and 9; Morelli's SIDPAC `fdoe`): the states are the measured outputs (C = I),
the longitudinal axis (V, α, q, θ) is driven by elevator and throttle, the lateral axis
(β, p, r, φ) by aileron and rudder, and each axis is a 4-state linear model

    ẋ = A x + B u_eff,   y = x + v,

fitted where the excitation put its power. In the frequency domain, with X(ω) the finite
Fourier transform of a record of length T at ω_k = 2πk/T (k ≠ 0), the model reads exactly

    X(ω_k) = (jω_k I − A)⁻¹ (B U_eff(ω_k) − d),

where d = x(T) − x(0) is the record's transient term (Pintelon & Schoukens, *System
Identification: A Frequency Domain Approach*, 2012, §6.3): it carries whatever initial and
final state the record has, so no periodicity and no steady state are needed, and a constant
offset (a trim error) lives only at DC, which is not fitted. The cost is independent of the
record's length: only the bins up to the band's top are used.

Each axis is fitted on its excited bins only (`excited`): those where one of its own
controls puts at least EXCITED_LEVEL of its largest bin's power, as Morelli's `fdoe` fits the
excited frequencies. Everything else in the band carries no information about the axis
and is where the nonlinear distortion goes. The full preset plays odd harmonics, each
control on its own. A lateral manoeuvre reaches the longitudinal axis through even functions
of β, p, r: sideslip drag ∝ |β| explains all of the Cub's nonlinear airspeed residual and
half its pitch-acceleration residual. Those functions of odd-harmonic signals sit on even
harmonics, away from the elevator's lines. On JSBSim's Cub in calm air this took the short
period from 31 % to 2.6 % off.

1. Equation error: each state's row, jωX_i = A_i X + B_i U − d_i, by linear least squares
   over the bins: the start.
2. Output error: J = Σ_k Σ_i w_i² |Y_i(ω_k) − X_i(ω_k; θ)|², Levenberg–Marquardt with the
   exact Jacobian, the weights w_i = 1/σ_i re-estimated from the residuals between passes
   (the relaxation of Maine & Iliff, NASA RP-1138 §5.3). The output-error estimate is
   consistent under any noise independent of the inputs — turbulence included — and its
   covariance is estimated from the residuals bin by bin (the sandwich H⁻¹ (Σ_k g_k g_kᵀ) H⁻¹
   with g_k the gradient of bin k): frequency bins are nearly independent for long records,
   so this holds for coloured noise (turbulence) where the white-noise Cramér–Rao bound
   (JᵀJ)⁻¹σ² does not.
3. Inputs: surfaces are measured positions; the throttle reaches the thrust through the
   engine's spin-up, modelled as THROTTLE_LAGS first-order lags whose time constants are
   estimated (u_eff = u / Π(1 + jωτ)). Held inputs (commands recorded at the sample) carry
   the zero-order hold's half-sample delay and sinc; sampled ones are taken at face value.

Sideslip drag (`prepare`): where β is measured, β² (the vane's air-relative β, from trim) is
a known input of V̇'s equation alone, with a fitted gain: drag due to sideslip, C_D ∝ β²
(Klein & Morelli's drag models). Odd-harmonic inputs keep even-order effects off the
longitudinal lines only while β stays periodic. When the bank drifts (the spiral mode), the
sideslip's slow wander puts sideslip drag on the throttle's lines. On JSBSim's Cub in calm
air the phugoid was 1 % or 8 % off depending only on the relative sign of the aileron's and
rudder's multisines; with the term, 0.6 % and 2.6 %. Free on every longitudinal row instead,
its gains were collinear with the short period's and cost it 4 %.

Kinematics and wind (`prepare`), used when the record carries them. With the trim
(`operating_point`), the equations of θ and φ are pure kinematics (θ̇ = q cos φ − r sin φ,
φ̇ = p + tan θ (q sin φ + r cos φ)). Their rows of A and the θ, φ columns of the other rows
(gravity's: no force depends on the attitude) are fixed at the kinematics' linear part at
the trim (_Problem). Their nonlinear rest is a known forcing K, X = (sI − A)⁻¹(B U + K − d),
so the bank of a lateral manoeuvre stops biasing the phugoid: with the lateral inputs
playing, the r sin φ of θ̇ can be larger than q itself. The V̇, α̇ and β̇ equations get no such
forcing. Their kinematic nonlinearities share factors such as 1/(V cos β) with the unknown
aerodynamic force, so half of a nonlinear equation is not nearer the truth than none. On
the Cub, α̇'s kinematic remainder alone moved the short period by 30 %. With the INS's
heading and velocities too, the wind is measured and its gusts become known inputs (see
`prepare`).

Coupling, reported either way (`coupling`): each axis model is fitted again with the other
axis's controls added, and again with the other axis's measured states (θ and φ aside, which
the kinematics already carry) added as known inputs. The fraction of its weighted cost each
explains is reported, and how much they change its outputs. Each joins on its own test, when
it changes the outputs by more than COUPLED:
- where the longitudinal controls reach the lateral axis, the throttle joins it, through the
  engine's lags (the propeller's torque and slipstream act linearly and at once). The
  elevator does not: it has no path to the lateral forces but through the longitudinal
  states. Lateral controls never join the longitudinal axis, whose forces are even in the
  lateral variables;
- the other axis's states join either axis. Their gains are the coupling blocks of the
  assembled A (Klein & Morelli, ch. 9: the other axis's measured states as inputs), so the
  modes are the coupled aircraft's.
At the other axis's lines its states are its controls' response, so the two overlap there.
Letting only the one that explains more of the cost join would make the model's structure
hang on a near tie: on JSBSim's Cub in calm air the two shares are nearly equal, the choice
flips from seed to seed, and the spiral with it (z about 1 or 3.3).

The lateral derivatives' change with α (`prepare`): where both axes are fitted together,
α·β, α·p and α·r (the still-air states, from trim) are known inputs of the lateral axis, with
fitted gains (reported as `alpha_products`). The longitudinal manoeuvre moves α while the
lateral one plays, and C_lβ, C_nβ, C_lp, C_lr and C_nr vary with α (JSBSim's Cub tabulates
C_lβ and C_lr against it). The products fall on the sum and difference frequencies of the two
axes' lines, some of which are the lateral axis's own. With the products, the spiral's
z-score over `make bench-jsbsim`'s 60 flights fell from rms 1.35 to 1.29 (against
`--without alpha-products`): the Cub's calm-air mean from +2.2 to +1.1, while the Cessna
182's rose from +0.5 to +1.4. The lateral record alone moves α too little: no products.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.ndimage

from agent.ident.errors import DataError, IdentificationFailed
from agent.ident.okid import Experiment

LONGITUDINAL = (("airspeed", "alpha", "q", "theta"), ("elevator", "throttle"))
LATERAL = (("beta", "p", "r", "phi"), ("aileron", "rudder"))
AXES = {"longitudinal": LONGITUDINAL, "lateral": LATERAL}
# Engine spin-up between throttle and thrust, as this many equal first-order lags of one
# estimated time constant (2: manifold pressure and engine speed; JSBSim's piston engines show
# poles at 1–3 and 1–10 1/s). Two separate time constants are not identifiable apart from
# each other in a minute of data (the fit wanders along τ1 ↔ τ2).
THROTTLE_LAGS = 2
LAG_START_S = 0.3
# The analysis band: from the first bin to BAND_MARGIN × the highest frequency where an input
# has INPUT_LEVEL of its largest bin's power, at most a quarter of the sample rate.
BAND_MARGIN = 1.5
INPUT_LEVEL = 0.01
# Excited bins (`excited`): a control's bins with at least this share of its largest bin's power.
EXCITED_LEVEL = 0.01
# Output error's weights: σ per bin from the residuals of this many bins on either side.
SMOOTH_BINS = 8
SMOOTH_FLOOR = 0.3
# Output error: passes of noise re-weighting, iterations per pass, and their stopping rules.
PASSES = 4
ITERATIONS = 40
RELATIVE_DECREASE = 1e-9
NOISE_TOLERANCE = 0.02
# Coupling tests (see the module docstring): the throttle or the other axis's states join an
# axis's inputs when, added, they change its outputs by more than COUPLED of their rms
# (weighted by the noise). The share of the cost they explain cannot tell: on a perfect fit it
# is a share of the last digits (10 % of a 10⁻⁸ residual on a linear aircraft, while the
# outputs change by 10⁻⁴). On JSBSim's three the lateral axis changes by 1.6–7 % with the
# throttle (the propeller's torque and slipstream), and each axis by 1.3–7.6 % with the other's
# states, mostly through the propeller's gyroscopic moments (the Cub's q̇ = … − 0.52 r).
COUPLED = 0.01


# Not frequency.Spectra: transforms at the analysis bins, not densities averaged over segments.
@dataclass(frozen=True)
class Spectra:
    """Finite Fourier transforms of the batch at the analysis bins (bins of all records)."""

    s: np.ndarray  # (F,) jω
    Y: np.ndarray  # (F, m)
    U: np.ndarray  # (F, r)
    record: np.ndarray  # (F,) which experiment each bin comes from
    band_hz: tuple[float, float]
    K: np.ndarray | None = None  # (F, m) known forcing of each output's equation (kinematics)
    # The kinematics' linear part at the trim in output columns (m × m; zero where only forces
    # act), and the output columns of θ and φ, whose rows and columns it fixes (see _Problem).
    kinematics: np.ndarray | None = None
    attitude: tuple[int, ...] = ()
    # Known inputs that enter one equation only: input column → output column (sideslip drag
    # acts on V̇ alone).
    rows: Mapping[int, int] = field(default_factory=dict)


@dataclass(frozen=True)
class AxisFit:
    """One fitted model: ẋ = A x + B u_eff with the states the outputs `states` (C = I)."""

    name: str  # "longitudinal" or "lateral"
    states: tuple[int, ...]  # output columns
    inputs: tuple[int, ...]  # input columns
    A: np.ndarray
    B: np.ndarray
    lags: dict[int, float]  # input column → the time constant of its THROTTLE_LAGS lags, s
    transients: np.ndarray  # d per experiment (E, n), complex
    covariance: np.ndarray  # of [vec A, vec B] (row-major)
    noise_std: np.ndarray  # σ_i of the frequency-domain residuals, per state (rms over bins)
    bin_std: np.ndarray  # σ per fitted bin and state, the fit's weights (`_sigma`)
    cost_start: float
    cost: float
    iterations: int
    converged: bool
    controls: tuple[int, ...] = ()  # the inputs whose excited bins the fit used (`excited`)
    # Lagged input → its number of lags where it is not THROTTLE_LAGS (a gust rate's one).
    lag_powers: dict[int, int] = field(default_factory=dict)


def spectra(
    batch: Sequence,
    dt: float,
    band_hz: float | None,
    held_inputs: bool,
    known: Sequence[np.ndarray] | None = None,
    kinematics: np.ndarray | None = None,
    attitude: Sequence[int] = (),
    rows: Mapping[int, int] | None = None,
) -> Spectra:
    """Transforms of every experiment (X = Δt · DFT) at the bins in the analysis band;
    `known`: per experiment, a known forcing of each output's equation (samples × outputs);
    `kinematics`, `attitude` and `rows`: see Spectra."""
    top = band_hz or input_band(batch, dt)
    top = min(top, 0.25 / dt)
    parts = []
    for index, exp in enumerate(batch):
        n = exp.u.shape[0]
        f = np.fft.rfftfreq(n, dt)
        keep = (f > 0) & (f <= top)
        if keep.sum() == 0:
            continue
        s = 2j * np.pi * f[keep]
        U = np.fft.rfft(exp.u, axis=0)[keep] * dt
        Y = np.fft.rfft(exp.y, axis=0)[keep] * dt
        K = np.zeros_like(Y) if known is None else np.fft.rfft(known[index], axis=0)[keep] * dt
        if held_inputs:  # a zero-order hold: half a sample late, and its sinc
            w = np.abs(s) * dt / 2
            U = U * (np.exp(-s * dt / 2) * np.sinc(w / np.pi))[:, None]
        parts.append((s, Y, U, np.full(s.size, index), K))
    if not parts:
        raise DataError("the records are too short for a single frequency bin in the band")
    s, Y, U, record, K = (np.concatenate(p) for p in zip(*parts, strict=True))
    return Spectra(
        s,
        Y,
        U,
        record,
        (float(np.abs(s).min() / 2 / np.pi), float(top)),
        K,
        kinematics,
        tuple(attitude),
        dict(rows or {}),
    )


def excited(sp: Spectra, controls: Sequence[int]) -> Spectra:
    """The bins where one of `controls` puts at least EXCITED_LEVEL of its largest bin's
    power, in each record."""
    keep = np.zeros(sp.s.size, dtype=bool)
    for e in np.unique(sp.record):
        mine = sp.record == e
        power = np.abs(sp.U[mine][:, list(controls)]) ** 2
        keep[mine] = np.any(power >= EXCITED_LEVEL * power.max(axis=0), axis=1)
    K = None if sp.K is None else sp.K[keep]
    return replace(sp, s=sp.s[keep], Y=sp.Y[keep], U=sp.U[keep], record=sp.record[keep], K=K)


def input_band(batch: Sequence, dt: float) -> float:
    """BAND_MARGIN × the highest frequency where an input puts at least INPUT_LEVEL of its
    largest bin's power (a multisine's top line, a doublet's main lobe; measured positions'
    noise floor lies far below)."""
    tops = [0.0]
    for exp in batch:
        u = exp.u - exp.u.mean(axis=0)
        power = np.abs(np.fft.rfft(u, axis=0)) ** 2
        f = np.fft.rfftfreq(u.shape[0], dt)
        for column in power.T:
            if column.max() > 0:
                tops.append(float(f[np.flatnonzero(column >= INPUT_LEVEL * column.max())[-1]]))
    return BAND_MARGIN * max(tops)


class _Problem:
    """The output-error problem of one model: parameters θ = [vec A, vec B, τ, Re d, Im d].

    Where the kinematics are known (Spectra.kinematics), what holds no aerodynamic parameter is
    fixed rather than fitted: the rows of θ and φ (pure kinematics: θ̇ = q cos φ − r sin φ,
    φ̇ = p + tan θ (q sin φ + r cos φ); their inputs' gains are zero) and the columns of θ and
    φ (no force depends on the attitude; gravity does, through the kinematics). Left free,
    output error used them to absorb what it could not model: on JSBSim's Cub it fitted
    θ̇ = 1.37 q and an airspeed equation with 11 q in it. The kinematics' linear terms in
    the other axis's states join the known forcing."""

    def __init__(
        self,
        sp: Spectra,
        states,
        inputs,
        lagged: Sequence[int],
        experiments: int,
        controls: Sequence[int] = (),
        powers: Mapping[int, int] | None = None,
    ):
        states, inputs = list(states), list(inputs)
        if controls:
            sp = excited(sp, controls)
        self.s = sp.s
        self.Y = sp.Y[:, states]
        self.U = sp.U[:, inputs]
        self.K = 0.0 if sp.K is None else sp.K[:, states]
        self.record = sp.record
        self.n, self.r = len(states), len(inputs)
        self.lagged = [inputs.index(j) for j in lagged]  # positions among inputs
        self.nlag = len(self.lagged)
        # Each lagged input's number of first-order lags (the throttle's THROTTLE_LAGS unless
        # `powers` says otherwise: a gust rate has one).
        self.powers = [(powers or {}).get(inputs[j], THROTTLE_LAGS) for j in self.lagged]
        self.experiments = experiments
        self.size = self.n * self.n + self.n * self.r + self.nlag + 2 * self.n * experiments
        n, r = self.n, self.r
        self.fixed_A = np.zeros((n, n), dtype=bool)
        self.fixed_B = np.zeros((n, r), dtype=bool)
        self.A0 = np.zeros((n, n))
        if sp.kinematics is not None:
            J = sp.kinematics
            local = [i for i, c in enumerate(states) if c in sp.attitude]
            self.fixed_A[local, :] = True
            self.fixed_A[:, local] = True
            self.fixed_B[local, :] = True
            self.A0 = J[np.ix_(states, states)] * self.fixed_A
            others = [c for c in range(sp.Y.shape[1]) if c not in states]
            if others:  # the other axis's states through the kinematics' linear terms
                self.K = self.K + sp.Y[:, others] @ J[np.ix_(states, others)].T
        for column, row in sp.rows.items():  # a known input of one equation only
            if column in inputs:
                j = inputs.index(column)
                self.fixed_B[[i for i, c in enumerate(states) if c != row], j] = True
        self.free = np.concatenate(
            [
                ~self.fixed_A.ravel(),
                ~self.fixed_B.ravel(),
                np.ones(self.size - n * n - n * r, dtype=bool),
            ]
        )

    def unpack(self, theta: np.ndarray):
        n, r = self.n, self.r
        A = theta[: n * n].reshape(n, n)
        B = theta[n * n : n * n + n * r].reshape(n, r)
        i = n * n + n * r
        taus = theta[i : i + self.nlag]
        i += self.nlag
        d = theta[i:].reshape(2, self.experiments, n)
        return A, B, taus, d[0] + 1j * d[1]

    def pack(self, A, B, taus, d) -> np.ndarray:
        return np.concatenate(
            [A.ravel(), B.ravel(), np.ravel(taus), d.real.ravel(), d.imag.ravel()]
        )

    def effective_inputs(self, taus: np.ndarray) -> np.ndarray:
        U = self.U.copy()
        for k, j in enumerate(self.lagged):
            U[:, j] = U[:, j] / (1 + self.s * taus[k]) ** self.powers[k]
        return U

    def response(self, theta: np.ndarray, jacobian: bool = False):
        """Model transforms X (F, n) and, when asked, ∂X/∂θ (F, n, P)."""
        A, B, taus, d = self.unpack(theta)
        n = self.n
        S = np.linalg.inv(self.s[:, None, None] * np.eye(n) - A)
        Ue = self.effective_inputs(taus)
        forcing = Ue @ B.T + self.K - d[self.record]
        X = np.einsum("fij,fj->fi", S, forcing)
        if not jacobian:
            return X, None
        F = self.s.size
        J = np.zeros((F, n, self.size), dtype=complex)
        # ∂X/∂A_ij = S e_i X_j ;  ∂X/∂B_ij = S e_i U_j
        J[:, :, : n * n] = np.einsum("fki,fj->fkij", S, X).reshape(F, n, n * n)
        col = n * n
        J[:, :, col : col + n * self.r] = np.einsum("fki,fj->fkij", S, Ue).reshape(F, n, -1)
        col += n * self.r
        for k, j in enumerate(self.lagged):
            grad = Ue[:, j] * -self.powers[k] * self.s / (1 + self.s * taus[k])
            J[:, :, col] = (S @ B[:, j]) * grad[:, None]
            col += 1
        for e in range(self.experiments):
            mine = self.record == e
            for i in range(n):
                J[mine, :, col + e * n + i] = -S[mine, :, i]
                J[mine, :, col + (self.experiments + e) * n + i] = -1j * S[mine, :, i]
        return X, J


def equation_error(problem: _Problem) -> np.ndarray:
    """Starting parameters: each row jωX_i = A_i X + B_i U − d_i by least squares, over the
    row's free entries (the fixed ones' terms move to the left-hand side)."""
    taus = np.full(problem.nlag, LAG_START_S)
    s, Y, n, r = problem.s, problem.Y, problem.n, problem.r
    U = problem.effective_inputs(taus)
    E = problem.experiments
    onehot = (problem.record[:, None] == np.arange(E)[None, :]).astype(float)
    reg = np.hstack([Y, U])
    A = problem.A0.copy()
    B = np.zeros((n, r))
    d = np.zeros((E, n), dtype=complex)
    known = np.broadcast_to(problem.K, Y.shape)
    for i in range(n):
        free = np.concatenate([~problem.fixed_A[i], ~problem.fixed_B[i]])
        lhs = s * Y[:, i] - known[:, i] - Y @ A[i]
        sub = reg[:, free]
        real = np.vstack(
            [np.hstack([sub.real, -onehot, 0 * onehot]), np.hstack([sub.imag, 0 * onehot, -onehot])]
        )
        coef, *_ = np.linalg.lstsq(real, np.concatenate([lhs.real, lhs.imag]), rcond=None)
        k = int(free.sum())
        row = np.zeros(n + r)
        row[free] = coef[:k]
        A[i] += row[:n] * ~problem.fixed_A[i]
        B[i] = row[n:]
        d[:, i] = coef[k : k + E] + 1j * coef[k + E :]
    return problem.pack(A, B, taus, d)


def output_error(problem: _Problem, theta: np.ndarray):
    """Levenberg–Marquardt on the weighted residuals, re-weighting between passes."""
    X, _ = problem.response(theta)
    sigma = _sigma(problem.Y - X, problem.s)
    cost_start = _cost(problem.Y - X, sigma)
    iterations, converged = 0, False
    for _ in range(PASSES):
        theta, its, converged = _minimise(problem, theta, sigma)
        iterations += its
        X, _ = problem.response(theta)
        new = _sigma(problem.Y - X, problem.s)
        settled = np.all(np.abs(new - sigma) <= NOISE_TOLERANCE * sigma)
        sigma = new
        if settled:
            break
    return theta, sigma, cost_start, iterations, converged


def _sigma(residual: np.ndarray, s: np.ndarray) -> np.ndarray:
    """σ per bin and output (F, n): the residual's rms over the SMOOTH_BINS nearest bins in
    frequency on either side. Turbulence's response is coloured, strong at the phugoid's
    frequencies and weak at the short period's. Weighting each bin by its own neighbourhood's
    level is the frequency-domain form of the filter-error method's noise model (Jategaonkar,
    ch. 5): an output's quiet bands then count for what they carry. A single σ per output
    would let its noisiest band set the weight of all of them."""
    power = np.abs(residual) ** 2
    if SMOOTH_BINS > 0 and power.shape[0] > 2 * SMOOTH_BINS + 1:
        order = np.argsort(np.abs(s), kind="stable")
        smooth = np.empty_like(power)
        smooth[order] = scipy.ndimage.uniform_filter1d(
            power[order], 2 * SMOOTH_BINS + 1, axis=0, mode="nearest"
        )
    else:
        smooth = np.broadcast_to(power.mean(axis=0), power.shape)
    # No band's weight beyond (1/SMOOTH_FLOOR)² times the output's average: a band the model
    # happens to fit to the last digits (noise-free data) must not take over the fit.
    floor = SMOOTH_FLOOR * np.sqrt(power.mean(axis=0))
    sigma = np.maximum(np.sqrt(np.maximum(smooth, 0.0)), floor)  # the filter rounds to −0
    return np.maximum(sigma, 1e-12 * max(float(sigma.max()), 1e-300))


def _cost(residual: np.ndarray, sigma: np.ndarray) -> float:
    return float(np.sum(np.abs(residual / sigma) ** 2))


def _stack(J: np.ndarray) -> np.ndarray:
    J = J.reshape(-1, J.shape[-1])
    return np.vstack([J.real, J.imag])


def _minimise(problem: _Problem, theta: np.ndarray, sigma: np.ndarray):
    lam = 1e-3
    free = problem.free
    X, J = problem.response(theta, jacobian=True)
    cost = _cost(problem.Y - X, sigma)
    for iteration in range(1, ITERATIONS + 1):
        e = (problem.Y - X) / sigma
        Jw = _stack(-J[:, :, free] / sigma[:, :, None])
        er = np.concatenate([e.ravel().real, e.ravel().imag])
        g, H = Jw.T @ er, Jw.T @ Jw
        scale = np.sqrt(np.maximum(np.diag(H), 1e-300))
        Hs = H / np.outer(scale, scale)
        gs = g / scale
        while True:
            try:
                step = -np.linalg.solve(Hs + lam * np.eye(gs.size), gs) / scale
            except np.linalg.LinAlgError:
                step = None
            if step is not None and np.all(np.isfinite(step)):
                trial = theta.copy()
                trial[free] += step
                Xt, _ = problem.response(trial)
                new = _cost(problem.Y - Xt, sigma) if np.all(np.isfinite(Xt)) else np.inf
                if new < cost:
                    break
            lam *= 10
            if lam > 1e10:
                return theta, iteration, True  # no step lowers the cost: a minimum
        decrease = (cost - new) / cost
        theta, cost, lam = trial, new, max(lam / 10, 1e-12)
        X, J = problem.response(theta, jacobian=True)
        if decrease < RELATIVE_DECREASE:
            return theta, iteration, True
    return theta, ITERATIONS, False


def covariance(problem: _Problem, theta: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Sandwich covariance of θ from the bin-wise gradients of the weighted cost."""
    X, J = problem.response(theta, jacobian=True)
    e = (problem.Y - X) / sigma
    free = problem.free
    Jw = -J[:, :, free] / sigma[:, :, None]
    H = _stack(Jw).T @ _stack(Jw)
    # Per bin k: g_k = Re(J_kᴴ e_k), the bin's share of the gradient (outputs together).
    g = np.einsum("fip,fi->fp", Jw.conj(), e).real
    Hinv = np.linalg.pinv(H, rcond=1e-12)
    out = np.zeros((theta.size, theta.size))
    out[np.ix_(free, free)] = Hinv @ (g.T @ g) @ Hinv  # the fixed entries are exact
    return out


def fit_axis(
    sp: Spectra,
    name: str,
    states,
    inputs,
    lagged,
    experiments: int,
    controls: Sequence[int] = (),
    powers: Mapping[int, int] | None = None,
) -> AxisFit:
    """One axis's model: `lagged` inputs reach it through fitted lags, THROTTLE_LAGS of them
    unless `powers` (input column → number) says otherwise."""
    powers = {j: p for j, p in (powers or {}).items() if j in lagged}
    problem = _Problem(sp, states, inputs, lagged, experiments, controls, powers)
    if problem.s.size * problem.n < problem.size:  # a record too short: bad input
        raise DataError(
            f"{name}: {problem.s.size} frequency bins cannot determine {problem.size} "
            "parameters; record longer or widen the band"
        )
    theta = equation_error(problem)
    theta, sigma, start, iterations, converged = output_error(problem, theta)
    A, B, taus, d = problem.unpack(theta)
    if not np.all(np.isfinite(A)):
        raise IdentificationFailed(f"{name}: the output-error fit diverged")
    cov = covariance(problem, theta, sigma)
    k = problem.n * problem.n + problem.n * problem.r
    lags = {list(inputs)[j]: float(abs(taus[i])) for i, j in enumerate(problem.lagged)}
    X, _ = problem.response(theta)
    noise = np.sqrt(np.mean(sigma**2, axis=0))
    return AxisFit(
        name,
        tuple(states),
        tuple(inputs),
        A,
        B,
        lags,
        d,
        cov[:k, :k],
        noise,
        sigma,
        start,
        _cost(problem.Y - X, sigma),
        iterations,
        converged,
        tuple(controls),
        powers,
    )


def coupling(sp: Spectra, fitted: AxisFit, other_inputs, experiments: int) -> tuple[float, float]:
    """What the other axis's inputs explain of an axis, from the decoupled fit with their
    columns added (started at zero) and fitted again: the fraction of its weighted cost, and
    the rms of the outputs' change as a fraction of the outputs' rms (weighted alike). The
    second tells a coupling the outputs show from the last digits of a perfect fit."""
    if not other_inputs:
        return 0.0, 0.0
    problem = _Problem(
        sp,
        fitted.states,
        (*fitted.inputs, *other_inputs),
        tuple(fitted.lags),
        experiments,
        fitted.controls,
        fitted.lag_powers,
    )
    B = np.hstack([fitted.B, np.zeros((fitted.B.shape[0], len(other_inputs)))])
    taus = np.array([fitted.lags[j] for j in fitted.lags])
    theta = problem.pack(fitted.A, B, taus, fitted.transients)
    X0 = problem.response(theta)[0]
    before = _cost(problem.Y - X0, fitted.bin_std)
    theta, _, _ = _minimise(problem, theta, fitted.bin_std)
    X1 = problem.response(theta)[0]
    after = _cost(problem.Y - X1, fitted.bin_std)
    signal = _cost(problem.Y, fitted.bin_std)
    fraction = max(0.0, 1.0 - after / before) if before > 0 else 0.0
    change = float(np.sqrt(_cost(X1 - X0, fitted.bin_std) / signal)) if signal > 0 else 0.0
    return fraction, change


def columns(names: Sequence[str | None], roles: Sequence[str]) -> list[int] | None:
    """Column of each role, or None when one is missing."""
    out = []
    for role in roles:
        if role not in names:
            return None
        out.append(list(names).index(role))
    return out


def axes_present(input_roles, output_roles) -> dict[str, tuple[list[int], list[int]]]:
    """The axes whose four outputs and at least one input the record carries."""
    present = {}
    for axis, (outs, ins) in AXES.items():
        states = columns(output_roles, outs)
        inputs = [list(input_roles).index(r) for r in ins if r in input_roles]
        if states is not None and inputs:
            present[axis] = (states, inputs)
    return present


# Rigid-body kinematics and gravity, known exactly (no aerodynamic parameter), for the eight
# states in this order. Their linear part about the trim is what A holds; what is left (the
# remainder) is a known forcing of each state's equation (`kinematic_remainder`).
KINEMATIC_STATES = ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
GRAVITY = 9.80665


def kinematics(x: np.ndarray) -> np.ndarray:
    """ẋ without aerodynamic and thrust forces and moments: the body velocity's rotation and
    gravity in V̇, α̇ and β̇, the Euler angles' rates in θ̇ and φ̇ (Stevens & Lewis, *Aircraft
    Control and Simulation*, §2.4), and nothing in ṗ, q̇, ṙ (their moments are all unknown).
    x: (..., 8) in KINEMATIC_STATES order, absolute values, SI units."""
    V, alpha, q, theta, beta, p, r, phi = np.moveaxis(x, -1, 0)
    u = V * np.cos(alpha) * np.cos(beta)
    v = V * np.sin(beta)
    w = V * np.sin(alpha) * np.cos(beta)
    u_dot = r * v - q * w - GRAVITY * np.sin(theta)
    v_dot = p * w - r * u + GRAVITY * np.sin(phi) * np.cos(theta)
    w_dot = q * u - p * v + GRAVITY * np.cos(phi) * np.cos(theta)
    V_dot = (u * u_dot + v * v_dot + w * w_dot) / V
    alpha_dot = (u * w_dot - w * u_dot) / (u * u + w * w)
    beta_dot = (V * v_dot - v * V_dot) / (V * V * np.cos(beta))
    theta_dot = q * np.cos(phi) - r * np.sin(phi)
    phi_dot = p + np.tan(theta) * (q * np.sin(phi) + r * np.cos(phi))
    zero = np.zeros_like(V)
    return np.stack([V_dot, alpha_dot, zero, theta_dot, beta_dot, zero, zero, phi_dot], axis=-1)


def kinematic_jacobian(trim: np.ndarray) -> np.ndarray:
    """∂kinematics/∂x at `trim` (8 × 8, central differences)."""
    step = 1e-6 * np.maximum(np.abs(trim), 1.0)
    jacobian = np.empty((8, 8))
    for j in range(8):
        up, down = trim.copy(), trim.copy()
        up[j] += step[j]
        down[j] -= step[j]
        jacobian[:, j] = (kinematics(up) - kinematics(down)) / (2 * step[j])
    return jacobian


def kinematic_remainder(x: np.ndarray, trim: np.ndarray) -> np.ndarray:
    """kinematics(x) less its first-order expansion about `trim`: the part a linear model's
    A cannot hold. (N, 8) → (N, 8)."""
    return kinematics(x) - kinematics(trim) - (x - trim) @ kinematic_jacobian(trim).T


def inertial_air_data(x: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The airspeed, α and β the aircraft would have in still air: the INS's velocity over the
    ground (north, east, down) turned into body axes by the Euler angles. `x`: (N, 8) absolute
    states in KINEMATIC_STATES order (θ and φ used); `navigation`: (N, 4) ψ, v_N, v_E, v_D.
    Returns (N, 3): V (m/s), α, β (rad)."""
    theta, phi = x[:, 3], x[:, 7]
    psi, vn, ve, vd = navigation.T
    cps, sps, cth, sth, cph, sph = (
        np.cos(psi),
        np.sin(psi),
        np.cos(theta),
        np.sin(theta),
        np.cos(phi),
        np.sin(phi),
    )
    u = cth * cps * vn + cth * sps * ve - sth * vd
    v = (sph * sth * cps - cph * sps) * vn + (sph * sth * sps + cph * cps) * ve + sph * cth * vd
    w = (cph * sth * cps + sph * sps) * vn + (cph * sth * sps - sph * cps) * ve + cph * cth * vd
    speed = np.sqrt(u * u + v * v + w * w)
    return np.column_stack([speed, np.arctan2(w, u), np.arcsin(v / np.maximum(speed, 1e-9))])


# Sideslip drag (module docstring): β² a known input of V̇'s equation.
SIDESLIP_DRAG = True
# The lateral derivatives' change with α (module docstring): α·β, α·p and α·r, known inputs of
# the lateral axis when both axes are fitted together.
BILINEAR = ("beta", "p", "r")


def known_gain(fit: AxisFit, column: int, row: int) -> tuple[float, float] | None:
    """A fitted input gain and its standard error: B[row, column] of `fit` (input and output
    columns), or None when the fit has no such input or state."""
    if column not in fit.inputs or row not in fit.states:
        return None
    i, j = fit.states.index(row), fit.inputs.index(column)
    n, r = len(fit.states), len(fit.inputs)
    k = n * n + i * r + j
    return float(fit.B[i, j]), float(np.sqrt(max(fit.covariance[k, k], 0.0)))


# The measured wind's components, the output they correct and the axis they act on.
GUSTS = (("airspeed", "longitudinal"), ("alpha", "longitudinal"), ("beta", "lateral"))
# The states whose equations are kinematics alone (no aerodynamic parameter): their rows of A
# and their columns elsewhere are fixed (_Problem) and the nonlinear rest of their kinematics
# is a known forcing (`prepare`).
ATTITUDE = ("theta", "phi")


# The gusts whose rate is a known input too, through GUST_RATE_LAGS fitted lags: Dryden's
# pitch-rate gust q_g = s α_g / (1 + τs), τ = 4b/πV (MIL-F-8785C; JSBSim's), the gust's
# gradient along the airframe. The yaw-rate gust from β_g changed nothing measurable on the
# benchmark aircraft, so it is left out.
GUST_RATES = ("alpha",)
GUST_RATE_LAGS = 1
# The measured gust's noise floor is its periodogram's mean above this fraction of the Nyquist
# frequency (no gust reaches there); its periodogram is smoothed over WIENER_BINS bins a side.
NOISE_FLOOR_FROM = 0.5
WIENER_BINS = 8


def measured_gust(g: np.ndarray) -> np.ndarray:
    """The gust's conditional mean given its noisy measurement g (samples): each frequency
    bin scaled by the Wiener gain max(0, 1 − N/P), P the smoothed periodogram and N the white
    noise floor (NOISE_FLOOR_FROM).

    Why: the measured gust is the INS's still-air α less the vane's, and it inherits both
    sensors' noise. Where the gust is weak — the short period's band on a light aircraft in
    light turbulence — that noise is as large as the gust, and a regressor with noise biases
    its own gain toward zero and the rest of the fit with it (errors in variables). Its
    conditional mean is a regressor whose error is uncorrelated with it, so linear gains
    fitted on it are consistent (regression calibration; Carroll, Ruppert, Stefanski &
    Crainiceanu, *Measurement Error in Nonlinear Models*, 2nd ed., 2006, ch. 4). In calm air
    the gain is zero almost everywhere and the measured "gust", pure noise, leaves the fit."""
    mean = float(g.mean())
    G = np.fft.rfft(g - mean)
    P = np.abs(G) ** 2
    smooth = scipy.ndimage.uniform_filter1d(P, 2 * WIENER_BINS + 1, mode="nearest")
    floor = float(np.mean(P[int(NOISE_FLOOR_FROM * P.size) :]))
    gain = np.clip(1.0 - floor / np.maximum(smooth, 1e-300), 0.0, 1.0)
    return np.fft.irfft(gain * G, n=g.size) + mean


@dataclass(frozen=True)
class Prepared:
    """A batch made ready for the fit: outputs on their inertial footing where the wind is
    measured, the measured gusts appended to the inputs, and the kinematic forcing."""

    batch: list[Experiment]  # u: the controls, then the known inputs
    known: list[np.ndarray] | None  # kinematic remainder per experiment, or None
    gusts: tuple[str, ...]  # the gust columns' outputs ("airspeed", "alpha", "beta")
    extra_names: tuple[str, ...]  # the known inputs' names ("gust alpha", "beta²", ...)
    extra_axes: dict[int, str]  # known input column (index in u) → the axis it acts on
    gust_rms: dict[str, float]
    kinematics: np.ndarray | None = None  # see Spectra.kinematics (mean over experiments)
    attitude: tuple[int, ...] = ()  # output columns of θ and φ
    rates: tuple[int, ...] = ()  # known input columns of gust rates (GUST_RATE_LAGS lags each)
    rows: dict[int, int] = field(default_factory=dict)  # see Spectra.rows
    bilinear: tuple[int, ...] = ()  # known input columns of α·β, α·p, α·r (BILINEAR)


def prepare(
    batch: Sequence[Experiment],
    output_roles: Sequence[str | None],
    trim_samples: int = 1,
    dt: float = 1.0,
) -> Prepared:
    """Use the operating point and the INS's velocities when every experiment carries them.

    With the operating point, the exact kinematics' nonlinear remainder is a known forcing
    (`kinematic_remainder`). With the INS's velocities too, the wind is measured: the gust g is
    the still-air V, α, β (`inertial_air_data`) less the air data's. The forces depend on the
    air-relative states x − g but the states move as the inertial ones, ẋ_i = A(x_i − g) + B u,
    so the model is fitted on the inertial outputs with the gusts as known inputs of their
    own (free) gains: the vanes' reading of the gust stops being noise that biases the fit
    and becomes excitation. Its A is the still-air aircraft's.

    Two refinements, each measured on JSBSim's Cub in light turbulence (10 seeds, the full
    preset; short-period damping ratio's error, mean ± sd over seeds):
    - each gust is its conditional mean given the noisy measurement (`measured_gust`): the
      raw measured gust is as noisy as it is strong in the short period's band, and as a
      regressor it biased the fit;
    - the α gust's rate, with GUST_RATE_LAGS fitted lags, is a known input of the
      longitudinal axis: Dryden's pitch-rate gust s α_g/(1 + τs), τ = 4b/πV. Without it the
      short period's damping ratio came out 3.2 % low on every seed, even without sensor noise
      (−3.2 ± 0.4 %, both roots about 30 % off); with it −0.5 ± 0.5 %. Fitted on the raw
      measured gust it did not help (the noise again), on its conditional mean it does.
    `dt` (s): the records' sample time, for the gust rates."""
    index = {role: k for k, role in enumerate(output_roles) if role is not None}
    r = batch[0].u.shape[1]
    if "airspeed" not in index or any(e.operating_point is None for e in batch):
        return Prepared([Experiment(e.u, e.y) for e in batch], None, (), (), {}, {})
    measured = "theta" in index and all(e.navigation is not None for e in batch)
    gusts = tuple(role for role, _ in GUSTS if role in index) if measured else ()
    rated = [role for role in GUST_RATES if role in gusts]
    drag = SIDESLIP_DRAG and "beta" in index
    bilinear = bool(BILINEAR) and all(role in index for role in ("alpha", *BILINEAR))
    lateral = [KINEMATIC_STATES.index(role) for role in BILINEAR]
    out, known, jacobians, squares, count = [], [], [], dict.fromkeys(gusts, 0.0), 0
    for e in batch:
        x = np.zeros((e.y.shape[0], len(KINEMATIC_STATES)))
        for k, role in enumerate(KINEMATIC_STATES):
            if role in index:
                x[:, k] = e.y[:, index[role]] + e.operating_point[index[role]]
        u, y = e.u, e.y.copy()
        # Sideslip drag's regressor: the air-relative β (the vane's), before the wind's
        # correction below puts the inertial β in its place.
        beta = x[:, KINEMATIC_STATES.index("beta")]
        beta = beta - beta[:trim_samples].mean()
        if gusts:
            still = inertial_air_data(x, e.navigation)
            columns = []
            for role in gusts:
                k = KINEMATIC_STATES.index(role)
                inertial = still[:, ("airspeed", "alpha", "beta").index(role)]
                gust = inertial - x[:, k]
                gust = measured_gust(gust)
                columns.append(gust)
                squares[role] += float(np.sum((gust - gust.mean()) ** 2))
                x[:, k] = inertial
                y[:, index[role]] = inertial - e.operating_point[index[role]]
            columns += [np.gradient(columns[gusts.index(role)], dt) for role in rated]
            u = np.hstack([u, np.column_stack(columns)])
        if drag:
            u = np.hstack([u, (beta * beta)[:, None]])
        if bilinear:  # on the still-air states, as the model's (x − trim)
            deviation = x - x[:trim_samples].mean(axis=0)
            alpha = deviation[:, KINEMATIC_STATES.index("alpha")]
            u = np.hstack([u, alpha[:, None] * deviation[:, lateral]])
        count += y.shape[0]
        trim = x[:trim_samples].mean(axis=0)
        jacobians.append(kinematic_jacobian(trim))
        remainder = kinematic_remainder(x, trim)
        forcing = np.zeros_like(y)
        for role in ATTITUDE:
            if role in index:
                forcing[:, index[role]] = remainder[:, KINEMATIC_STATES.index(role)]
        out.append(Experiment(u, y))
        known.append(forcing)
    axes = dict(GUSTS)
    names = tuple(f"gust {role}" for role in gusts)
    where = [axes[role] for role in gusts]
    rates = tuple(r + len(names) + k for k in range(len(rated)))
    names = (*names, *(f"gust {role} rate" for role in rated))
    where = [*where, *(axes[role] for role in rated)]
    rows = {}
    if drag:
        rows[r + len(names)] = index["airspeed"]
        names = (*names, "beta²")
        where = [*where, "longitudinal"]
    products = ()
    if bilinear:
        products = tuple(r + len(names) + k for k in range(len(BILINEAR)))
        names = (*names, *(f"alpha·{role}" for role in BILINEAR))
        where = [*where, *(["lateral"] * len(BILINEAR))]
    m = batch[0].y.shape[1]
    J = np.zeros((m, m))
    mean = np.mean(jacobians, axis=0)
    present = [(k, index[role]) for k, role in enumerate(KINEMATIC_STATES) if role in index]
    for a, ca in present:
        for b, cb in present:
            J[ca, cb] = mean[a, b]
    attitude = tuple(index[role] for role in ATTITUDE if role in index)
    return Prepared(
        out,
        known,
        gusts,
        names,
        {r + k: a for k, a in enumerate(where)},
        {role: float(np.sqrt(v / count)) for role, v in squares.items()},
        J,
        attitude,
        rates,
        rows,
        products,
    )
