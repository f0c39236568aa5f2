"""The lateral axis of a closed-loop record refined by prediction error in the time domain:
the rolling gust as coloured process noise.

No sensor measures the rolling gust: MIL-F-8785C's Dryden p_g, the vertical gust's gradient
across the span, a moment L_p·p_g on the roll equation (and N_p·p_g on the yaw one), of
first-order spectrum with its break near πV/(4b) (1.7 1/s for a glider at 27 m/s with a
12.8 m span). The INS and the vanes measure the lateral gust (β's) and its rate, not it
(agent.ident.aircraft.prepare). Frequency-domain output error (agent.ident.aircraft.fit)
takes it as noise independent of the inputs: consistent in open loop. With the loop closed
(FBWA) the ailerons answer the gust and the inputs are correlated with the noise: output
error is then biased, JSBSim's SGS 1-26's roll mode 39–47 % off the truth in light
turbulence (benchmarks/closed_loop_check.py), and the frequency-domain filter error
(agent.ident.aircraft.process), which conditions on the inputs bin by bin, barely moves it
(30–37 %). Nor is it the inputs' noise: the surfaces projected on the injected stick signals
(the two-stage method) leave it at 44 %.

The prediction-error method is consistent under feedback when its noise model can hold the
disturbance (Ljung, *System Identification*, 2nd ed., 1999, §13.4: the direct approach), as
the time-domain filter-error method of Maine & Iliff (NASA RP-1138, 1985, ch. 7) and
Jategaonkar (*Flight Vehicle System Identification*, 2nd ed., 2015, ch. 5) is: the noisy
aerodynamic equations (p's; β's and r's too where β's gust is not a known input, the vanes
measuring β: agent.ident.aircraft.model) each get a first-order noise state w_i of its own
estimated pole a_i, ẋ = A x + B u + K(t) + c + Σ e_i w_i, ẇ_i = −a_i w_i + white, the
outputs y = x + sensor noise, and the fit minimises the one-step prediction errors of the
innovation form x̂(k+1) = Φ x̂ + Γ u + K (y − x̂), the predictor gain K (every entry)
estimated with A, B (the frequency-domain fit's structure: the kinematics' rows and columns
fixed, and what the structure's selection zeroed), the noise poles, the constant c (trim
errors: the transforms leave DC out, the time domain does not) and the initial state
(agent.ident.refine: Levenberg–Marquardt on the exact Jacobian, the outputs' weights
re-estimated between passes, the covariance corrected for the innovations' remaining
colour). The known inputs are those of the frequency-domain fit (the measured gusts, their
rates through the fitted lags, the α products, the other axis's states where they joined)
and K(t) the kinematics' nonlinear rest; the lags keep their fitted time constants. The fit
is to the outputs' means over blocks (RATE_HZ), modelled exactly: the state carried across
each block at the record's rate by the block's own input samples, the block's mean output
predicted from it (agent.ident.lifted). The blocks' means taken instead as the samples of a
first-order hold between them, as before, are not the aircraft's response to a card's
steps within a block: the SGS 1-26's light-turbulence card came out with its roll 6.5–22.9 %
slow (5 seeds of 10 within 10 %), lifted within 8.8 % (10 of 10); a calm, noise-free J-3
Cub card forced through the refinement 15.8 % off, lifted 0.2 %.

Measured (benchmarks/README.md, *Closed-loop excitation*): the SGS 1-26's closed-loop roll
mode in light turbulence within 10 % of the open loop's on three seeds of three (30–39 %
apart by output error). In open loop, where output error is consistent, only where output
error's roll mode is imprecise (PRECISE): where output error already knows the roll, the
noise model's own error only costs. In moderate turbulence the refinement's roll comes out
fast: the T-6's card, noise-free, on the two seeds of three it refined 15.6 and 14.9 % (the
hold's approximation 17.4 and 24.7 %), output error 16.5 and 4.9 %; with noise states on β's
and r's equations too 2.6 and 9.5 %, but the glider's light card then 9 of 10 for 10
(docs/limitations.md).
Not where β was synthesised from the INS (agent.ident.aircraft.model).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg
import scipy.signal
import scipy.stats

from agent.ident.aircraft import process
from agent.ident.aircraft.fit import (
    AxisFit,
    excited_tic,
    minimise,
    smooth_bins,
    weighted_cost,
)
from agent.ident.aircraft.prepare import Prepared
from agent.ident.aircraft.problem import THROTTLE_LAGS, AxisProblem
from agent.ident.aircraft.transforms import Transforms
from agent.ident.convert import StateSpace, discretize_hold
from agent.ident.errors import IdentificationFailed
from agent.ident.fit import simulate_states
from agent.ident.lifted import block_means, discretize_blocks, lift
from agent.ident.naming import DUTCH_ROLL_MAX_DAMPING, SPIRAL_MIN_TIME_CONSTANT
from agent.ident.okid import Experiment
from agent.ident.refine import Refinement, eigenvalue_std, refine

# The fit's sample rate, Hz, at least: the record's samples averaged in blocks of the largest
# whole number that keeps it, a low-pass that leaves the modes (the means are modelled
# exactly, so the rate costs no accuracy through the hold). Higher rates weight what lies
# beyond the modes, where the turbulence's structure differs most from the noise model's, and
# each Levenberg–Marquardt step's cost grows with the samples. Not the fit's band: in closed
# loop the surfaces follow the sensors' noise and the band reaches its ceiling (the J-3
# Cub's 25 Hz).
RATE_HZ = 12.5
# Each noise state's pole at the start, 1/s: near Dryden's roll gust's break (module text).
NOISE_POLE = 1.0
# The starting predictor gain is the steady-state Kalman gain of the noise states' intensity
# at each of these shares of the outputs' white noise (per step, as a rate): the one whose
# predictor fits best starts the search.
START_LEVELS = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)
# A noisy equation's output fitted at the excited bins with a Theil coefficient below this
# leaves too little for a noise model to hold (`shows_process_noise`): JSBSim's aircraft in
# light turbulence leave 0.2–0.5 on p's, a linear aircraft whose gusts are all measured 10⁻⁴.
MATERIAL = 0.05
# The search ends when a step lowers the cost by less than this share of it, and after PASSES
# re-weightings of the outputs at most: at 10⁻⁴ the SGS 1-26's light-turbulence roll mode
# came out 0.8 % off the truth where 10⁻⁵ gave 0.6 % (its σ about 6 %), in 20 iterations
# instead of 50.
SETTLED = 1e-4
PASSES = 2
# The noise model's yardstick (`misfit_to_noise`): the draws of the innovation model's
# disturbance whose residual power gives the ratio's spread, their generator's seed (the
# result does not change between runs), and the tail probability on either side of the
# band the suggestion's fit step accepts (agent.models).
NOISE_DRAWS = 2000
NOISE_SEED = 0
NOISE_TAIL = 0.001


# In open loop output error is consistent, and the refinement is used only where output
# error's roll mode is not known to ±10 % (the product's target) at two of its σ, or not
# found: then the rolling gust's own response, which the noise model reads and output error
# leaves as noise, is where the roll's information lies (`roll_imprecise`). Where output
# error already knows it, the noise model's own error only costs: ten seeds, open loop,
# output error's roll σ 3.6–4.9 % on the J-3 Cub's moderate-turbulence sweep and 2.6–3.7 % on
# the T-6's, the refinement's roll 8.1 and 14.9 % off in median there (output error 3.0 and
# 2.6 %); on the SGS 1-26's light-turbulence card output error's σ 10–25 %, its roll more
# than 10 % off (or missing) on 9 seeds of 10, the refinement's within 10 % on 9 of 10, and
# on its sweep 9 of 10 too (benchmarks/README.md).
PRECISE = 0.05


def roll_imprecise(fit: AxisFit) -> bool:
    """Whether `fit`'s (output error's) roll mode is missing or its relative σ above
    PRECISE or unknown: the roll as agent.ident.naming names it, the fastest
    non-oscillatory eigenvalue of the axis, stable and faster than a spiral can be."""
    n = fit.A.shape[0]
    lam = np.linalg.eigvals(fit.A)
    std = eigenvalue_std(fit.A, fit.covariance[: n * n, : n * n])
    reals = [
        k
        for k, s in enumerate(lam)
        if abs(s.imag) < 1e-9 or -s.real / abs(s) >= DUTCH_ROLL_MAX_DAMPING
    ]
    if not reals:
        return True
    k = max(reals, key=lambda k: abs(lam[k]))
    if lam[k].real >= 0 or abs(lam[k]) <= 1.0 / SPIRAL_MIN_TIME_CONSTANT:
        return True
    return not std[k].frequency <= PRECISE * abs(lam[k])  # an unknown (nan) σ: imprecise


@dataclass(frozen=True)
class Predicted:
    """What the prediction-error fit found beyond the axis model: each noise state's pole
    (1/s) by the output of its equation, and the innovations' σ per output."""

    poles: dict[int, float]  # output column → the pole of its equation's noise state
    innovation_std: np.ndarray
    # Per state of the axis (rows as `states`): its misfit power at the excited bins over what
    # the noise model leaves there, and that ratio's central band for the noise alone
    # (`misfit_to_noise`): [ratio, low, high].
    misfit: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def shows_process_noise(fit: AxisFit, problem: AxisProblem, rows: Sequence[int]) -> bool:
    """Whether the frequency-domain fit leaves process noise worth a model on `rows`: one of
    their outputs' Theil coefficient at the excited bins at least MATERIAL, and the
    filter-error method's likelihood ratio against white sensor noise alone
    (agent.ident.aircraft.process.significant) above its threshold at the fit. Where output
    error explains the excited bins (a record whose known inputs hold the disturbance, or
    sensor noise alone) it is efficient, and exact on a linear aircraft; the block averages
    would only cost it (a noise-free linear aircraft whose gusts are all measured, its inputs
    steps: its worst mode 0.02 % off by output error, 1.1 % refined)."""
    if max(float(fit.tic_excited[i]) for i in rows) < MATERIAL:
        return False
    theta = _theta(fit, problem, fit.A, fit.B)
    try:
        noise = process.estimate(problem, theta, tuple(rows), smooth_bins)
        _, width = smooth_bins(fit.bin_std, problem.s)
        return bool(process.significant(problem, theta, noise, width))
    except np.linalg.LinAlgError:  # spectra that do not converge: none shown
        return False


def lagged(signal: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """`signal` through one first-order lag of time constant `tau` (s), from rest (Tustin)."""
    a = dt / (2 * tau)
    return scipy.signal.lfilter([a / (1 + a), a / (1 + a)], [1.0, (a - 1) / (1 + a)], signal)


def series(fit: AxisFit, ready: Prepared, sp: Transforms, dt: float) -> list[Experiment]:
    """Per experiment, the axis's inputs in the time domain (through their fitted lags), the
    kinematics' forcing of its states, and its outputs: u = [inputs, forcing], y."""
    width = sp.U.shape[1]
    states = list(fit.states)
    out = []
    for e, prepared in enumerate(ready.batch):
        columns = []
        for j in fit.inputs:
            x = prepared.u[:, j] if j < width else prepared.y[:, j - width]
            x = np.array(x, dtype=float)
            if j in fit.lags:
                for _ in range(fit.lag_powers.get(j, THROTTLE_LAGS)):
                    x = lagged(x, fit.lags[j], dt)
            columns.append(x)
        forcing = np.zeros((prepared.y.shape[0], len(states)))
        if ready.known is not None:
            forcing += ready.known[e][:, states]
        if sp.kinematics is not None:
            others = [c for c in range(prepared.y.shape[1]) if c not in states]
            forcing += prepared.y[:, others] @ sp.kinematics[np.ix_(states, others)].T
        out.append(Experiment(np.column_stack([*columns, forcing]), prepared.y[:, states]))
    return out


def refined(
    fit: AxisFit,
    problem: AxisProblem,
    ready: Prepared,
    sp: Transforms,
    *,
    dt: float,
    hold: str,
    rows: Sequence[int],
) -> tuple[AxisFit, Predicted]:
    """`fit` refined by prediction error (module text), a noise state on each of `rows`
    (positions among its states). `problem`: the frequency-domain problem the fit solved
    (its fixed entries); `sp`: the record's transforms (the kinematics' Jacobian, the width of
    its inputs). Raises IdentificationFailed when the predictor cannot be fitted (it diverges
    from every start)."""
    n, r = fit.A.shape[0], fit.B.shape[1]
    rows = list(rows)
    nw = len(rows)
    size = n + nw
    # The outputs averaged in blocks (RATE_HZ), the inputs lifted (agent.ident.lifted).
    # Picking every step-th sample instead aliased the noise above the band into it (the
    # SGS 1-26's roll mode 13 % off at 50 Hz, 3 % averaged).
    step = max(1, int(np.floor(1.0 / (dt * RATE_HZ) + 1e-9)))
    block = step if step > 1 else None
    lengths = np.array([prepared.y.shape[0] * dt for prepared in ready.batch])
    batch = [
        Experiment(np.hstack([e.u, np.ones((e.u.shape[0], 1))]), e.y)
        for e in series(fit, ready, sp, dt)
    ]
    width = r + n + 1  # inputs, forcing, constant
    A = np.zeros((size, size))
    A[:n, :n] = fit.A
    for k, i in enumerate(rows):
        A[i, n + k] = 1.0
        A[n + k, n + k] = -NOISE_POLE
    B = np.zeros((size, width))
    B[:n, :r] = fit.B
    B[:n, r : r + n] = np.eye(n)
    fixed_A = np.ones((size, size), dtype=bool)
    fixed_A[:n, :n] = problem.fixed_A
    fixed_A[n:, n:] = ~np.eye(nw, dtype=bool)
    fixed_B = np.ones((size, width), dtype=bool)
    fixed_B[:n, :r] = problem.fixed_B
    fixed_B[[i for i in range(n) if not problem.fixed_A[i].all()], -1] = False  # c
    C = np.hstack([np.eye(n), np.zeros((n, nw))])
    model = StateSpace(A, B, C, np.zeros((n, width)))
    # Bad input: a record too short for two blocks has no prediction to fit.
    if any(e.y.shape[0] < 2 * step + 1 for e in batch):
        raise IdentificationFailed(
            f"{fit.name}: a record shorter than two blocks of {step * dt:.3g} s"
        )
    starts = [np.concatenate([block_means(e.y, step)[0], np.zeros(nw)]) for e in batch]
    gain = _start_gain(model, batch, rows, dt, hold, starts, block)
    # A trial step may make the predictor diverge: its cost is then inf and the step refused.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        result = _refine(model, dt, batch, gain, fixed_A, fixed_B, hold, starts, block)
    Ac, Bc = result.continuous.A, result.continuous.B
    if not (np.all(np.isfinite(Ac)) and np.all(np.isfinite(Bc))):
        raise IdentificationFailed(f"{fit.name}: the prediction-error fit diverged")
    index_a = np.arange(size * size).reshape(size, size)[:n, :n]
    index_b = size * size + np.arange(size * width).reshape(size, width)[:n, :r]
    keep = np.concatenate([index_a.ravel(), index_b.ravel()])
    A_fit, B_fit = Ac[:n, :n].copy(), Bc[:n, :r].copy()
    # The frequency-domain record of the new model: its transients fitted again (they enter
    # linearly), so the excited bins' TIC (the suggestion's fit step) and the cost are its own.
    theta = _theta(fit, problem, A_fit, B_fit)
    transients_only = _transients_only(problem)
    theta, _, _ = minimise(transients_only, theta, fit.bin_std)
    *_, transients = problem.unpack(theta)
    axis = replace(
        fit,
        A=A_fit,
        B=B_fit,
        transients=transients,
        covariance=result.covariance[np.ix_(keep, keep)],
        spread=None,  # the time domain's covariance, not a sandwich over bins
        cost=weighted_cost(problem, theta, fit.weights),
        iterations=fit.iterations + result.iterations,
        converged=result.converged,
        tic_excited=excited_tic(problem, theta),
    )
    poles = {fit.states[i]: float(-Ac[n + k, n + k]) for k, i in enumerate(rows)}
    misfit = misfit_to_noise(problem, theta, fit.bin_std, result, lengths)
    return axis, Predicted(poles=poles, innovation_std=result.noise_std, misfit=misfit)


def misfit_to_noise(
    problem: AxisProblem,
    theta: np.ndarray,
    weights: np.ndarray,
    result: Refinement,
    lengths: np.ndarray,
) -> np.ndarray:
    """Each state's misfit power at `problem`'s (excited) bins over what the prediction-error
    model's own noise leaves there, with that ratio's central band for the noise alone:
    (n, 3) rows [ratio, low, high] (nan where the model has no response).

    The model claims y = G u + v, v = H(z) e the innovation form's disturbance, H(z) = I +
    C (zI − Φ)⁻¹ K, e white of the innovations' variances Σe at the blocks' interval Tb
    (`result`). Its finite Fourier transform over a record of length T (`lengths`, s, per
    experiment) has at ω the covariance T·Tb·H Σe Hᴴ, bins asymptotically independent
    (Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2012, §6.3
    for its leakage: the transient term), and the frequency-domain record's transients,
    re-fitted by weighted least squares (`weights`: the fit's σ per bin and state), take their
    share of it. NOISE_DRAWS draws of that disturbance with the transients' share projected
    out give the power the model expects and its spread; the band is the gamma distribution
    of those moments (Satterthwaite's approximation of a weighted sum of χ²) at NOISE_TAIL on
    either side. Where the noise is coloured the expected power lies in few bins and the band
    is wide."""
    X, J = problem.response(theta, jacobian=True)
    n = problem.n
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(result.discrete.A))):
        return np.full((n, 3), np.nan)
    Phi, C, K = result.discrete.A, result.discrete.C, result.gain
    z = np.exp(problem.s * result.dt)
    H = np.eye(n) + C @ np.linalg.solve(z[:, None, None] * np.eye(Phi.shape[0]) - Phi, K)
    S = (lengths[problem.record] * result.dt)[:, None, None] * (
        H * result.noise_std**2 @ H.conj().transpose(0, 2, 1)
    )
    transients = J[:, :, problem.size - 2 * n * problem.experiments :]
    power = _residual_power_draws(S, transients, weights)
    mean = power.mean(axis=0)
    shape = 1.0 / np.maximum(np.var(power / mean, axis=0), 1e-12)
    low = scipy.stats.gamma.ppf(NOISE_TAIL, shape, scale=1.0 / shape)
    high = scipy.stats.gamma.ppf(1.0 - NOISE_TAIL, shape, scale=1.0 / shape)
    ratio = np.sum(np.abs(problem.Y - X) ** 2, axis=0) / mean
    return np.column_stack([ratio, low, high])


def _residual_power_draws(S: np.ndarray, transients: np.ndarray, weights: np.ndarray):
    """(NOISE_DRAWS, n) each output's power summed over the bins of a disturbance drawn
    with covariance S (F, n, n) per bin, less its weighted least-squares fit by the
    transients' columns (F, n, q), as the frequency-domain record's transients take it."""
    F, n = weights.shape
    values, vectors = np.linalg.eigh(S)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]  # S = root rootᴴ
    Jd = transients / weights[:, :, None]
    Q, _ = np.linalg.qr(np.vstack([Jd.real.reshape(F * n, -1), Jd.imag.reshape(F * n, -1)]))
    rng = np.random.default_rng(NOISE_SEED)
    powers = []
    for first in range(0, NOISE_DRAWS, 250):  # in chunks: memory stays small on long records
        draws = min(250, NOISE_DRAWS - first)
        Z = rng.standard_normal((draws, F, n)) + 1j * rng.standard_normal((draws, F, n))
        V = np.einsum("fij,dfj->dfi", root, Z / np.sqrt(2)) / weights
        stacked = np.hstack([V.real.reshape(draws, -1), V.imag.reshape(draws, -1)])
        left = stacked - (stacked @ Q) @ Q.T
        R = (left[:, : F * n] + 1j * left[:, F * n :]).reshape(draws, F, n) * weights
        powers.append(np.sum(np.abs(R) ** 2, axis=1))
    return np.vstack(powers)


def _refine(
    model: StateSpace,
    dt: float,
    batch: Sequence[Experiment],
    gain: np.ndarray,
    fixed_A: np.ndarray,
    fixed_B: np.ndarray,
    hold: str,
    starts: Sequence[np.ndarray],
    block: int | None,
) -> Refinement:
    """agent.ident.refine's prediction-error fit of the augmented model (`fixed_A`,
    `fixed_B`: its entries held at their values) to the means of `batch`'s blocks."""
    return refine(
        model,
        dt,
        batch,
        output_coordinates=True,
        estimate_d=False,
        hold=hold,
        gain=gain,
        fixed=np.concatenate([fixed_A.ravel(), fixed_B.ravel()]),
        initial_states=starts,
        relative_decrease=SETTLED,
        max_passes=PASSES,
        block=block,
    )


def _theta(fit: AxisFit, problem: AxisProblem, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """`problem`'s parameters with A and B, and `fit`'s lags and transients."""
    taus = np.array([fit.lags[fit.inputs[j]] for j in problem.lagged])
    return problem.pack(A, B, taus, fit.transients)


def _transients_only(problem: AxisProblem) -> AxisProblem:
    """A copy of `problem` whose only free parameters are the transients (its last ones)."""
    moved = copy.copy(problem)
    moved.free = np.zeros_like(problem.free)
    moved.free[problem.size - 2 * problem.n * problem.experiments :] = True
    return moved


def _start_gain(
    model: StateSpace,
    batch: Sequence[Experiment],
    rows: Sequence[int],
    dt: float,
    hold: str,
    starts: Sequence[np.ndarray],
    block: int | None,
) -> np.ndarray:
    """The steady-state Kalman gain, among START_LEVELS of the noise states' intensity, whose
    predictor's weighted one-step errors are smallest, for the means of `batch`'s blocks
    (`dt` its step). The outputs' white noise is guessed from their block-to-block
    differences."""
    n = model.C.shape[0]
    size = model.A.shape[0]
    if block is None:
        disc = discretize_hold(model.A, model.B, model.C, model.D, dt, hold)
    else:
        disc = discretize_blocks(model, dt, hold, block)
        batch = [Experiment(lift(e.u, block), block_means(e.y, block)) for e in batch]
        dt = dt * block
    y = np.vstack([np.diff(e.y, axis=0) for e in batch])
    white = np.maximum(np.var(y, axis=0) / 2, 1e-30)
    best, chosen = np.inf, np.zeros((size, n))
    for level in START_LEVELS:
        Q = np.zeros((size, size))
        for k, i in enumerate(rows):
            Q[n + k, n + k] = level * white[i] / dt**2
        try:
            P = scipy.linalg.solve_discrete_are(disc.A.T, disc.C.T, Q, np.diag(white))
        except (np.linalg.LinAlgError, ValueError):
            continue
        K = disc.A @ P @ disc.C.T @ np.linalg.inv(disc.C @ P @ disc.C.T + np.diag(white))
        cost = _prediction_cost(disc, K, batch, starts, white)
        if cost < best:
            best, chosen = cost, K
    if not np.isfinite(best):
        raise IdentificationFailed("no starting predictor for the prediction-error fit")
    return chosen


def _prediction_cost(
    disc: StateSpace,
    K: np.ndarray,
    batch: Sequence[Experiment],
    starts: Sequence[np.ndarray],
    white: np.ndarray,
) -> float:
    """Σ of the one-step prediction errors squared, each output over its white noise: x̂(k+1) =
    Φ x̂ + Bd u + K (y − C x̂ − Dd u)."""
    predictor = StateSpace(
        disc.A - K @ disc.C,
        np.hstack([disc.B - K @ disc.D, K]),
        disc.C,
        np.zeros((disc.C.shape[0], 0)),
    )
    total = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for e, x in zip(batch, starts, strict=True):
            states = simulate_states(predictor, np.hstack([e.u, e.y]), x)
            predicted = states @ disc.C.T + e.u @ disc.D.T
            total += float(np.sum((e.y - predicted) ** 2 / white))
    return total if np.isfinite(total) else np.inf
