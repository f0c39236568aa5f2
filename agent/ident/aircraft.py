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

Kinematics and wind (`prepare`), used when the record carries them: with the trim
(`operating_point`), the rigid body's exact kinematics and gravity less their linear part about
the trim are a known forcing K of each state's equation, X = (sI − A)⁻¹(B U + K − d), so the
bank and sideslip of a lateral manoeuvre stop biasing the phugoid (with the lateral inputs
playing, the r sin φ of θ̇ = q cos φ − r sin φ can be larger than q itself). With the INS's
heading and velocities too, the wind is measured and its gusts become known inputs (see
`prepare`).

Coupling, reported either way (`coupling`): each axis model is fitted again with the other
axis's inputs added, and again with the other axis's measured states added as known inputs;
the fraction of its weighted cost each explains is reported. The longitudinal controls join
the lateral axis's inputs when they explain more than COUPLED (the propeller's torque and
slipstream; the axes' dynamics stay separate); lateral controls never join the longitudinal
axis, whose forces are even in the lateral variables. States that explain more
than COUPLED_STATES mean the axes cannot be separated: one eight-state model with every input
(still C = I) is fitted and reported instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

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
# Output error: passes of noise re-weighting, iterations per pass, and their stopping rules.
PASSES = 4
ITERATIONS = 40
RELATIVE_DECREASE = 1e-9
NOISE_TOLERANCE = 0.02
# Coupling tests (see the module docstring): the other axis's controls join an axis's inputs
# when they explain more than COUPLED of its weighted cost (the propeller's torque and
# slipstream make the throttle yaw and roll a single-engine aircraft: 16–46 % of the lateral
# cost on JSBSim's three). The axes are fitted as one coupled model only when the other axis's
# measured states explain more than COUPLED_STATES: on JSBSim's aircraft they explain 10–38 %
# (even-order effects such as the drag of sideslip, which a linear coupling term only mimics)
# while the decoupled models are right to within 5 % in calm air and the coupled one is worse.
COUPLED = 0.1
COUPLED_STATES = 0.5


@dataclass(frozen=True)
class Spectra:
    """Finite Fourier transforms of the batch at the analysis bins (bins of all records)."""

    s: np.ndarray  # (F,) jω
    Y: np.ndarray  # (F, m)
    U: np.ndarray  # (F, r)
    record: np.ndarray  # (F,) which experiment each bin comes from
    band_hz: tuple[float, float]
    K: np.ndarray | None = None  # (F, m) known forcing of each output's equation (kinematics)


@dataclass(frozen=True)
class AxisFit:
    """One fitted model: ẋ = A x + B u_eff with the states the outputs `states` (C = I)."""

    name: str  # "longitudinal", "lateral" or "coupled"
    states: tuple[int, ...]  # output columns
    inputs: tuple[int, ...]  # input columns
    A: np.ndarray
    B: np.ndarray
    lags: dict[int, float]  # input column → the time constant of its THROTTLE_LAGS lags, s
    transients: np.ndarray  # d per experiment (E, n), complex
    covariance: np.ndarray  # of [vec A, vec B] (row-major)
    noise_std: np.ndarray  # σ_i of the frequency-domain residuals, per state
    cost_start: float
    cost: float
    iterations: int
    converged: bool


def spectra(batch: Sequence, dt: float, band_hz: float | None, held_inputs: bool,
            known: Sequence[np.ndarray] | None = None) -> Spectra:  # fmt: skip
    """Transforms of every experiment (X = Δt · DFT) at the bins in the analysis band;
    `known`: per experiment, a known forcing of each output's equation (samples × outputs)."""
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
    return Spectra(s, Y, U, record, (float(np.abs(s).min() / 2 / np.pi), float(top)), K)


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
    """The output-error problem of one model: parameters θ = [vec A, vec B, τ, Re d, Im d]."""

    def __init__(self, sp: Spectra, states, inputs, lagged: Sequence[int], experiments: int):
        self.s = sp.s
        self.Y = sp.Y[:, list(states)]
        self.U = sp.U[:, list(inputs)]
        self.K = 0.0 if sp.K is None else sp.K[:, list(states)]
        self.record = sp.record
        self.n, self.r = len(states), len(inputs)
        self.lagged = [list(inputs).index(j) for j in lagged]  # positions among inputs
        self.nlag = len(self.lagged)
        self.experiments = experiments
        self.size = self.n * self.n + self.n * self.r + self.nlag + 2 * self.n * experiments

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
        return np.concatenate([A.ravel(), B.ravel(), np.ravel(taus), d.real.ravel(),
                               d.imag.ravel()])  # fmt: skip

    def effective_inputs(self, taus: np.ndarray) -> np.ndarray:
        U = self.U.copy()
        for k, j in enumerate(self.lagged):
            U[:, j] = U[:, j] / (1 + self.s * taus[k]) ** THROTTLE_LAGS
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
            grad = Ue[:, j] * -THROTTLE_LAGS * self.s / (1 + self.s * taus[k])
            J[:, :, col] = (S @ B[:, j]) * grad[:, None]
            col += 1
        for e in range(self.experiments):
            mine = self.record == e
            for i in range(n):
                J[mine, :, col + e * n + i] = -S[mine, :, i]
                J[mine, :, col + (self.experiments + e) * n + i] = -1j * S[mine, :, i]
        return X, J


def equation_error(problem: _Problem) -> np.ndarray:
    """Starting parameters: each row jωX_i = A_i X + B_i U − d_i by least squares."""
    s, Y, U, n = problem.s, problem.Y, problem.U, problem.n
    E = problem.experiments
    onehot = (problem.record[:, None] == np.arange(E)[None, :]).astype(float)
    reg = np.hstack([Y, U])
    real = np.vstack([np.hstack([reg.real, -onehot, 0 * onehot]),
                      np.hstack([reg.imag, 0 * onehot, -onehot])])  # fmt: skip
    A = np.zeros((n, n))
    B = np.zeros((n, problem.r))
    d = np.zeros((E, n), dtype=complex)
    known = np.broadcast_to(problem.K, Y.shape)
    for i in range(n):
        lhs = s * Y[:, i] - known[:, i]
        coef, *_ = np.linalg.lstsq(real, np.concatenate([lhs.real, lhs.imag]), rcond=None)
        A[i], B[i] = coef[:n], coef[n : n + problem.r]
        d[:, i] = coef[n + problem.r : n + problem.r + E] + 1j * coef[n + problem.r + E :]
    taus = np.full(len(problem.lagged), LAG_START_S)
    return problem.pack(A, B, taus, d)


def output_error(problem: _Problem, theta: np.ndarray):
    """Levenberg–Marquardt on the weighted residuals, re-weighting between passes."""
    X, _ = problem.response(theta)
    sigma = _sigma(problem.Y - X)
    cost_start = _cost(problem.Y - X, sigma)
    iterations, converged = 0, False
    for _ in range(PASSES):
        theta, its, converged = _minimise(problem, theta, sigma)
        iterations += its
        X, _ = problem.response(theta)
        new = _sigma(problem.Y - X)
        settled = np.all(np.abs(new - sigma) <= NOISE_TOLERANCE * sigma)
        sigma = new
        if settled:
            break
    return theta, sigma, cost_start, iterations, converged


def _sigma(residual: np.ndarray) -> np.ndarray:
    sigma = np.sqrt(np.mean(np.abs(residual) ** 2, axis=0))
    return np.maximum(sigma, 1e-12 * max(float(sigma.max()), 1e-300))


def _cost(residual: np.ndarray, sigma: np.ndarray) -> float:
    return float(np.sum(np.abs(residual / sigma) ** 2))


def _stack(J: np.ndarray) -> np.ndarray:
    J = J.reshape(-1, J.shape[-1])
    return np.vstack([J.real, J.imag])


def _minimise(problem: _Problem, theta: np.ndarray, sigma: np.ndarray):
    lam = 1e-3
    X, J = problem.response(theta, jacobian=True)
    cost = _cost(problem.Y - X, sigma)
    for iteration in range(1, ITERATIONS + 1):
        e = (problem.Y - X) / sigma
        Jw = _stack(-J / sigma[None, :, None])
        er = np.concatenate([e.ravel().real, e.ravel().imag])
        g, H = Jw.T @ er, Jw.T @ Jw
        scale = np.sqrt(np.maximum(np.diag(H), 1e-300))
        Hs = H / np.outer(scale, scale)
        gs = g / scale
        while True:
            try:
                step = -np.linalg.solve(Hs + lam * np.eye(theta.size), gs) / scale
            except np.linalg.LinAlgError:
                step = None
            if step is not None and np.all(np.isfinite(step)):
                trial = theta + step
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
    Jw = -J / sigma[None, :, None]
    H = _stack(Jw).T @ _stack(Jw)
    # Per bin k: g_k = Re(J_kᴴ e_k), the bin's share of the gradient (outputs together).
    g = np.einsum("fip,fi->fp", Jw.conj(), e).real
    Hinv = np.linalg.pinv(H, rcond=1e-12)
    return Hinv @ (g.T @ g) @ Hinv


def fit_axis(sp: Spectra, name: str, states, inputs, lagged, experiments: int) -> AxisFit:
    problem = _Problem(sp, states, inputs, lagged, experiments)
    if problem.s.size * problem.n < problem.size:
        raise IdentificationFailed(
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
    return AxisFit(name, tuple(states), tuple(inputs), A, B, lags, d, cov[:k, :k], sigma,
                   start, _cost(problem.Y - X, sigma), iterations, converged)  # fmt: skip


def coupling(sp: Spectra, fitted: AxisFit, other_inputs, experiments: int) -> float:
    """Fraction of an axis's weighted cost that the other axis's inputs explain, from the
    decoupled fit with their columns added (started at zero) and fitted again."""
    if not other_inputs:
        return 0.0
    problem = _Problem(sp, fitted.states, (*fitted.inputs, *other_inputs), tuple(fitted.lags),
                       experiments)  # fmt: skip
    B = np.hstack([fitted.B, np.zeros((fitted.B.shape[0], len(other_inputs)))])
    taus = np.array([fitted.lags[j] for j in fitted.lags])
    theta = problem.pack(fitted.A, B, taus, fitted.transients)
    before = _cost(problem.Y - problem.response(theta)[0], fitted.noise_std)
    theta, _, _ = _minimise(problem, theta, fitted.noise_std)
    after = _cost(problem.Y - problem.response(theta)[0], fitted.noise_std)
    return max(0.0, 1.0 - after / before) if before > 0 else 0.0


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


def kinematic_remainder(x: np.ndarray, trim: np.ndarray) -> np.ndarray:
    """kinematics(x) less its first-order expansion about `trim`: the part a linear model's
    A cannot hold. (N, 8) → (N, 8). A trim a little off changes the remainder only by terms
    linear in x, which A absorbs."""
    step = 1e-6 * np.maximum(np.abs(trim), 1.0)
    jacobian = np.empty((8, 8))
    for j in range(8):
        up, down = trim.copy(), trim.copy()
        up[j] += step[j]
        down[j] -= step[j]
        jacobian[:, j] = (kinematics(up) - kinematics(down)) / (2 * step[j])
    return kinematics(x) - kinematics(trim) - (x - trim) @ jacobian.T


def inertial_air_data(x: np.ndarray, navigation: np.ndarray) -> np.ndarray:
    """The airspeed, α and β the aircraft would have in still air: the INS's velocity over the
    ground (north, east, down) turned into body axes by the Euler angles. `x`: (N, 8) absolute
    states in KINEMATIC_STATES order (θ and φ used); `navigation`: (N, 4) ψ, v_N, v_E, v_D.
    Returns (N, 3): V (m/s), α, β (rad)."""
    theta, phi = x[:, 3], x[:, 7]
    psi, vn, ve, vd = navigation.T
    cps, sps, cth, sth, cph, sph = (np.cos(psi), np.sin(psi), np.cos(theta), np.sin(theta),
                                    np.cos(phi), np.sin(phi))  # fmt: skip
    u = cth * cps * vn + cth * sps * ve - sth * vd
    v = (sph * sth * cps - cph * sps) * vn + (sph * sth * sps + cph * cps) * ve + sph * cth * vd
    w = (cph * sth * cps + sph * sps) * vn + (cph * sth * sps - sph * cps) * ve + cph * cth * vd
    speed = np.sqrt(u * u + v * v + w * w)
    return np.column_stack([speed, np.arctan2(w, u), np.arcsin(v / np.maximum(speed, 1e-9))])


# The measured wind's components, the output they correct and the axis they act on.
GUSTS = (("airspeed", "longitudinal"), ("alpha", "longitudinal"), ("beta", "lateral"))


@dataclass(frozen=True)
class Prepared:
    """A batch made ready for the fit: outputs on their inertial footing where the wind is
    measured, the measured gusts appended to the inputs, and the kinematic forcing."""

    batch: list[Experiment]  # u: the controls, then the gusts
    known: list[np.ndarray] | None  # kinematic remainder per experiment, or None
    gusts: tuple[str, ...]  # the gust columns' outputs ("airspeed", "alpha", "beta")
    gust_axes: dict[int, str]  # gust column (index in u) → the axis it acts on
    gust_rms: dict[str, float]


def prepare(batch: Sequence[Experiment], output_roles: Sequence[str | None],
            trim_samples: int = 1) -> Prepared:  # fmt: skip
    """Use the operating point and the INS's velocities when every experiment carries them.

    With the operating point, the exact kinematics' nonlinear remainder is a known forcing
    (`kinematic_remainder`). With the INS's velocities too, the wind is measured: the gust g is
    the still-air V, α, β (`inertial_air_data`) less the air data's. The forces depend on the
    air-relative states x − g but the states move as the inertial ones, ẋ_i = A(x_i − g) + B u,
    so the model is fitted on the inertial outputs with the gusts as known inputs of their
    own (free) gains: the vanes' reading of the gust stops being noise that biases the fit
    and becomes excitation. Its A is the still-air aircraft's."""
    index = {role: k for k, role in enumerate(output_roles) if role is not None}
    r = batch[0].u.shape[1]
    if "airspeed" not in index or any(e.operating_point is None for e in batch):
        return Prepared([Experiment(e.u, e.y) for e in batch], None, (), {}, {})
    measured = "theta" in index and all(e.navigation is not None for e in batch)
    gusts = tuple(role for role, _ in GUSTS if role in index) if measured else ()
    out, known, squares, count = [], [], dict.fromkeys(gusts, 0.0), 0
    for e in batch:
        x = np.zeros((e.y.shape[0], len(KINEMATIC_STATES)))
        for k, role in enumerate(KINEMATIC_STATES):
            if role in index:
                x[:, k] = e.y[:, index[role]] + e.operating_point[index[role]]
        u, y = e.u, e.y.copy()
        if gusts:
            still = inertial_air_data(x, e.navigation)
            columns = []
            for role in gusts:
                k = KINEMATIC_STATES.index(role)
                inertial = still[:, ("airspeed", "alpha", "beta").index(role)]
                gust = inertial - x[:, k]
                columns.append(gust)
                squares[role] += float(np.sum((gust - gust.mean()) ** 2))
                x[:, k] = inertial
                y[:, index[role]] = inertial - e.operating_point[index[role]]
            u = np.hstack([u, np.column_stack(columns)])
        count += y.shape[0]
        remainder = kinematic_remainder(x, x[:trim_samples].mean(axis=0))
        forcing = np.zeros_like(y)
        for k, role in enumerate(KINEMATIC_STATES):
            if role in index:
                forcing[:, index[role]] = remainder[:, k]
        out.append(Experiment(u, y))
        known.append(forcing)
    axes = dict(GUSTS)
    return Prepared(out, known, gusts, {r + k: axes[role] for k, role in enumerate(gusts)},
                    {role: float(np.sqrt(v / count)) for role, v in squares.items()})  # fmt: skip
