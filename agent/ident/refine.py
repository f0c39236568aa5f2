"""Output-error refinement of an identified model, with Cramér–Rao standard errors.

OKID fits a one-step (observer) predictor: with sensor noise on the outputs its regression is
biased, and the bias grows with the noise (thesis table 6.6 shows how p changes the answer).
The maximum-likelihood estimate for white output noise instead minimises the simulation
error of the model driven by the measured inputs, the output-error method of SIDPAC and of
Maine & Iliff (*Identification of Dynamic Systems*, NASA RP-1138, 1985; Klein & Morelli,
*Aircraft System Identification*, AIAA 2006, ch. 6):

    J(θ) = Σ_k Σ_i (y_i(k) − ŷ_i(k; θ))² / σ_i²,

starting from the OKID/ERA model, with the initial state of every experiment among the
unknowns and the noise variances σ_i² re-estimated from the residuals between passes (the
relaxation algorithm of RP-1138 §5.3). The Jacobian is exact, from the output sensitivities
of the discrete model (`fit.state_convolution`), and the minimisation is Levenberg–Marquardt
on the normal equations. At the optimum (Jᵀ J)⁻¹ of the weighted Jacobian is the Cramér–Rao bound of
the parameters; it assumes white residuals, so with unmodelled dynamics the true scatter is
larger (Klein & Morelli §6.5).

With process noise (turbulence) the simulation error is not white and output error, though
consistent, wastes the data. The same machinery then fits the innovation form instead — the
prediction-error method (Ljung, *System Identification*, 2nd ed., 1999, ch. 7): the residual
is the one-step prediction error of x̂(k+1) = Φ x̂ + Bd u + K (y − C x̂ − Dd u), with the
predictor gain K (n × m) among the unknowns, started from OKID's observer gain (its observer
is this predictor, K = −G). Its residuals are the innovations, white under process and
sensor noise alike, so the Cramér–Rao reading holds again.

The parameters are those of the continuous model (Ac, Bc, and C, D where free), so the
standard errors are those of the stability and control derivatives of thesis appendix A. The
model is discretised at the analysis rate with the hold that matches the data: a zero-order
hold for inputs held between samples at the record rate, a first-order hold for decimated
(filtered, hence smooth) inputs — measured on the A.2 record decimated 50 → 10 Hz, fitting a
zero-order-hold model to smooth inputs biases the Dutch roll by 29 %. The Jacobian chains
the discrete output sensitivities with the Fréchet derivative of the matrix exponential (Van
Loan's block formula, *IEEE TAC* 23, 1978). When the model is in output coordinates (C = I)
every entry of Ac, Bc (and D when estimated) is free and identifiable. Otherwise A, B, C are
over-parametrised by the n² state coordinates; the search then moves only orthogonally to the
similarity orbit (data-driven local coordinates, McKelvey, Helmersson & Ribarits,
*Automatica* 40, 2004), which keeps the Jacobian full rank without fixing a canonical form.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.ndimage

from agent.ident.convert import StateSpace, discretize_hold, hold_derivatives
from agent.ident.errors import IdentificationFailed
from agent.ident.fit import (
    BLOCK_MAX,
    estimate_initial_state,
    free_response_basis,
    simulate,
    simulate_states,
    state_convolution_from,
)
from agent.ident.lifted import block_means, blocks_jacobian, discretize_blocks, lift
from agent.ident.modal import EigenvalueStd, Mode, SecondOrder
from agent.ident.okid import Experiment

# Noise re-weighting passes, and the relative change of every σ_i that ends them.
MAX_PASSES = 4
NOISE_TOLERANCE = 0.02
# Levenberg–Marquardt iterations per pass, and the relative cost decrease that ends a pass.
MAX_ITERATIONS = 30
RELATIVE_DECREASE = 1e-8
# σ_i never drops below this fraction of the output's RMS (noise-free data would divide by 0).
NOISE_FLOOR = 1e-9
# The correction for coloured residuals (`coloured_covariance`): the residuals' cross-spectra
# averaged over this many periodogram bins on either side (Daniell's window), and the largest
# Jacobian (entries, samples × outputs × parameters) it is computed on at once; a longer
# record is taken in segments of that size, their cross terms left out.
COLOURED_BINS = 8
COLOURED_ENTRIES = 20_000_000
# The small-sample correction of a sandwich standard error (`dof_factor`): the degrees of
# freedom are held at this floor, where the t distribution's variance ν/(ν − 2) is still
# finite and the Satterthwaite approximation from so few bins is itself rough.
DOF_FLOOR = 3.0


@dataclass(frozen=True, kw_only=True)
class Refinement:
    """The refined continuous model, its initial states and the Cramér–Rao covariance."""

    gain: np.ndarray | None  # K of the innovation form; None for output error
    continuous: StateSpace  # Ac, Bc, C, D
    discrete: StateSpace  # its discretisation at dt (what was fitted)
    dt: float
    hold: str  # "zoh" or "foh": how the fitted discretisation treats the inputs
    # The outputs were means over blocks of this many of the record's samples, dt the blocks'
    # interval and `discrete` their lifted model (agent.ident.lifted); None: the samples.
    block: int | None = None
    initial_states: tuple[np.ndarray, ...]
    noise_std: np.ndarray  # σ_i per output: of the final residuals (innovations for PEM)
    # Of [vec Ac, vec Bc, vec C, vec D] (row-major), fixed entries 0: corrected for the
    # residuals' colour (`coloured_covariance`).
    covariance: np.ndarray
    # Where the covariance is a sandwich over frequency bins (the whole-aircraft method): per
    # fitted axis, its bins' shares of a contrast's variance (bins, residual parts, columns)
    # and those columns' positions in the covariance's vector (`dof_factor`); else empty.
    spread: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    cost_initial: float  # weighted cost of the starting model (final σ)
    cost: float
    iterations: int
    passes: int
    # The last Levenberg–Marquardt pass ended because the cost stopped falling (by less than
    # RELATIVE_DECREASE, or no step lowered it), not at MAX_ITERATIONS: the estimate sits at a
    # minimum. When False the result is wherever the search stopped, and can move with the
    # data's last digits (seen on 6-state lateral models with two poorly excited extra poles).
    converged: bool = True

    @property
    def improvement(self) -> float:
        """Fraction by which the weighted simulation cost fell (0 = none)."""
        return 1.0 - self.cost / self.cost_initial if self.cost_initial > 0 else 0.0

    def covariance_of_a(self) -> np.ndarray:
        n = self.continuous.A.shape[0]
        return self.covariance[: n * n, : n * n]

    def spread_of_a(self) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """`spread` restricted to vec Ac's entries."""
        n = self.continuous.A.shape[0]
        out = []
        for G, pos in self.spread:
            keep = pos < n * n
            if keep.any():
                out.append((G[:, :, keep], pos[keep]))
        return tuple(out)

    def matrix_std(self) -> StateSpace:
        """Standard errors of Ac, Bc, C, D entry by entry (0 for entries held fixed), each
        widened for the few bins that carry it where `spread` says (`dof_factor`)."""
        std = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        return _unpack_matrices(
            std * entry_dof_factors(self.spread, std.size), *_shape(self.continuous)
        )


def _shape(model: StateSpace) -> tuple[int, int, int]:
    n, r = model.B.shape
    return n, model.C.shape[0], r


def _unpack_matrices(v: np.ndarray, n: int, m: int, r: int) -> StateSpace:
    sizes = np.cumsum([n * n, n * r, m * n, m * r])
    a, b, c, d, _ = np.split(v, sizes)
    return StateSpace(a.reshape(n, n), b.reshape(n, r), c.reshape(m, n), d.reshape(m, r))


def discretization_jacobian(
    model: StateSpace, dt: float, hold: str, moving: np.ndarray | None = None
) -> np.ndarray:
    """∂[vec Φ, vec Bd, vec C, vec Dd]/∂[vec Ac, vec Bc, vec C, vec D] of `discretize_hold`.

    The derivative of expm(M) along dM is the top-right block of expm([[M, dM], [0, M]]);
    all n² + n·r directions go through one batched expm, or only those `moving` (a mask
    over [vec Ac, vec Bc]) marks, the others' columns left zero (a structured model's fixed
    entries: no derivative is asked of them).
    """
    n, m, r = _shape(model)
    k = n * n + n * r
    Phi, _, G2, dPhi, dGa, dG2 = hold_derivatives(model.A, model.B, dt, hold, moving)
    if hold == "zoh":
        dBd, G2, dG2 = dGa, np.zeros_like(G2), np.zeros_like(dG2)
    else:
        dBd = dPhi @ G2 + Phi @ dG2 + dGa - dG2
    dDd = model.C @ dG2
    total = n * n + n * r + m * n + m * r
    chain = np.zeros((total, total))
    chain[: n * n, :k] = dPhi.reshape(k, -1).T
    chain[n * n : k, :k] = dBd.reshape(k, -1).T
    chain[k + m * n :, :k] = dDd.reshape(k, -1).T
    # C enters as itself and through Dd = D + C Γ2; D as itself.
    chain[k : k + m * n, k : k + m * n] = np.eye(m * n)
    for a in range(m):
        for j in range(n):
            dD = np.zeros((m, r))
            dD[a] = G2[j]
            chain[k + m * n :, k + a * n + j] = dD.ravel()
    chain[k + m * n :, k + m * n :] = np.eye(m * r)
    return chain


def _discretize(model: StateSpace, dt: float, hold: str, block: int | None) -> StateSpace:
    """The discrete model fitted: sampled at `dt` with `hold`, or of `block` means."""
    if block is None:
        return discretize_hold(model.A, model.B, model.C, model.D, dt, hold)
    return discretize_blocks(model, dt, hold, block)


def _discretization_chain(
    model: StateSpace, dt: float, hold: str, block: int | None, moving: np.ndarray
) -> np.ndarray:
    """`_discretize`'s derivative in the continuous model's entries."""
    if block is None:
        return discretization_jacobian(model, dt, hold, moving)
    return blocks_jacobian(model, dt, hold, block, moving)[1]


# Above this many (state × direction) sensitivities the Jacobian comes from one recursion of
# all directions (`_propagate`), below from the per-entry lifted convolution unless that one's
# m·n·width per sample is the more (block means' lifted inputs: agent.ident.lifted): measured,
# the crossover lies between the A.2 lateral case (n·q ≈ 120) and the 8-state models (n·q ≈
# 1000); on a lifted lateral axis of JSBSim's Cessna 182 (n·q ≤ 400, m·n·width ≈ 1800) the
# recursion took an identification 2.2 → 1.2 s.
DIRECT_SENSITIVITY_SIZE = 400


# The Jacobian is accumulated over stretches of a record (`OutputErrorProblem.evaluate`)
# holding about this many floats of sensitivities each, so its memory does not grow with the
# record: a record shorter than one stretch is done in one. Stretches are whole numbers of
# the lifted simulation's longest block (fit.BLOCK_MAX), which a streamed record's
# convolutions then use, so each stretch ends exactly.
STRETCH_FLOATS = 8_000_000


def _propagate(
    A: np.ndarray, forcing: np.ndarray, start: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """S(0) = start, S(k+1) = A S(k) + forcing(k) for (n × Q) matrices: (length × n × Q), and
    the S after the last sample."""
    out = np.empty_like(forcing)
    state = np.array(start, dtype=float)
    for k in range(forcing.shape[0]):
        out[k] = state
        state = A @ state + forcing[k]
    return out, state


def sample_stretches(length: int, per_sample: int) -> list[tuple[int, int]]:
    """[first, last) sample ranges covering `length`, each at most STRETCH_FLOATS floats of
    `per_sample`, every one but the last a multiple of BLOCK_MAX samples."""
    size = max(BLOCK_MAX, STRETCH_FLOATS // max(per_sample, 1) // BLOCK_MAX * BLOCK_MAX)
    if length <= size:
        return [(0, length)]
    return [(first, min(first + size, length)) for first in range(0, length, size)]


class OutputErrorProblem:
    """The weighted output-error residual and its exact Jacobian for one batch."""

    def __init__(
        self,
        model: StateSpace,
        dt: float,
        batch: Sequence[Experiment],
        x0s: Sequence[np.ndarray],
        free_c: bool,
        free_d: bool,
        hold: str,
        gain: np.ndarray | None = None,
        fixed: np.ndarray | None = None,
        block: int | None = None,
    ):
        """`fixed`: entries of [vec Ac, vec Bc] held at the model's values (a structured
        model's known or absent terms), or None. `block`: the outputs are means over blocks
        of this many of the record's steps (`dt`) and the inputs lifted
        (agent.ident.lifted), or None: samples at `dt`."""
        self.n, self.m, self.r = _shape(model)
        self.dt, self.hold, self.block = dt, hold, block
        self.batch = batch
        self.innovation = gain is not None
        n, m, r = self.n, self.m, self.r
        self.matrix_size = n * n + n * r + m * n + m * r
        self.states_at = self.matrix_size + n * m  # first x0 entry; K sits before it
        K = np.zeros((n, m)) if gain is None else np.asarray(gain, dtype=float)
        self.full0 = np.concatenate(
            [model.A.ravel(), model.B.ravel(), model.C.ravel(), model.D.ravel(), K.ravel(), *x0s]
        )
        # Which entries of the full vector move: Ac, Bc always; C, D as asked; K in the
        # innovation form; every x0.
        free = np.zeros(self.full0.size, dtype=bool)
        free[: n * n + n * r] = True
        free[n * n + n * r : n * n + n * r + m * n] = free_c
        free[n * n + n * r + m * n : self.matrix_size] = free_d
        free[self.matrix_size : self.states_at] = self.innovation
        free[self.states_at :] = True
        if fixed is not None:
            free[: n * n + n * r] &= ~np.asarray(fixed, dtype=bool)
        selection = np.eye(self.full0.size)[:, free]
        if free_c:
            # Drop the n² directions that only change state coordinates.
            orbit = selection.T @ self._orbit_tangent(model, K, x0s)
            self.basis = selection @ scipy.linalg.null_space(orbit.T)
        else:
            self.basis = selection
        self.weights = np.ones(m)

    def _orbit_tangent(
        self, model: StateSpace, K: np.ndarray, x0s: Sequence[np.ndarray]
    ) -> np.ndarray:
        """Columns: d(full vector) for z = (I + E_ab) x, one per (a, b)."""
        n = self.n
        cols = []
        for a in range(n):
            for b in range(n):
                E = np.zeros((n, n))
                E[a, b] = 1.0
                cols.append(
                    np.concatenate(
                        [
                            (E @ model.A - model.A @ E).ravel(),
                            (E @ model.B).ravel(),
                            (-model.C @ E).ravel(),
                            np.zeros(model.D.size),
                            (E @ K).ravel(),
                            *[E @ x0 for x0 in x0s],
                        ]
                    )
                )
        return np.column_stack(cols)

    def unpack(self, beta: np.ndarray) -> tuple[StateSpace, list[np.ndarray]]:
        v = self.full0 + self.basis @ beta
        model = _unpack_matrices(v[: self.matrix_size], self.n, self.m, self.r)
        x0s = np.split(v[self.states_at :], len(self.batch))
        return model, x0s

    def gain(self, beta: np.ndarray) -> np.ndarray:
        """K of the innovation form (zeros for output error)."""
        v = self.full0 + self.basis @ beta
        return v[self.matrix_size : self.states_at].reshape(self.n, self.m)

    def evaluate(
        self, beta: np.ndarray, jacobian: str | None = None
    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | np.ndarray | None]:
        """Weighted residuals (ŷ − y)/σ stacked over experiments, and what the Jacobian J in
        β gives: for `jacobian` "normal", (JᵀJ, Jᵀr); for "triangle", the triangular factor R
        of [J | r] (JᵀJ = RᵀR: J's singular values without J); "full": J itself (for checks;
        its memory grows with the record); None: nothing. J is built and summed stretch by
        stretch (`sample_stretches`), whole only when asked for.

        Output error: ŷ is the model simulated from the inputs. Innovation form: ŷ is the
        one-step prediction of x̂(k+1) = Φ x̂ + Bd u + K (y − C x̂ − Dd u), i.e. the system
        Ā = Φ − K C driven by v = [u; y] through B̄ = [Bd − K Dd, K].
        """
        with_jacobian = jacobian is not None
        cont, x0s = self.unpack(beta)
        K = self.gain(beta)
        n, m = self.n, self.m
        disc = _discretize(cont, self.dt, self.hold, self.block)
        r = disc.B.shape[1]  # the discrete model's inputs: lifted ones are more
        Abar = disc.A - K @ disc.C
        Bbar = np.hstack([disc.B - K @ disc.D, K])
        predictor = StateSpace(Abar, Bbar, disc.C, np.hstack([disc.D, np.zeros((m, m))]))
        width = n + r + (m if self.innovation else 0)  # signals driving the sensitivities
        # The Jacobian in β is (∂ŷ/∂discrete)(∂discrete/∂continuous)(∂continuous/∂β): the
        # last two are small, so they are multiplied first, and the sparse C and D blocks of
        # ∂ŷ/∂discrete are applied as matrix products instead of being built.
        G = None
        if with_jacobian:
            moving = np.any(self.basis[: n * n + n * self.r] != 0, axis=1)
            G = (
                _discretization_chain(cont, self.dt, self.hold, self.block, moving)
                @ self.basis[: self.matrix_size]
            )
            q = G.shape[1]
            k_ab = n * n + n * r
            dPhi = G[: n * n].reshape(n, n, q)
            dBd = G[n * n : k_ab].reshape(n, r, q)
            dC = G[k_ab : k_ab + m * n].reshape(m, n, q)
            dDd = G[k_ab + m * n :].reshape(m, r, q)
            dK = self.basis[self.matrix_size : self.states_at].reshape(n, m, q)
            # ∂Ā = ∂Φ − ∂K C − K ∂C; ∂B̄ = [∂Bd − ∂K Dd − K ∂Dd, ∂K].
            dAbar = dPhi - np.einsum("imq,mj->ijq", dK, disc.C) - np.einsum("im,mjq->ijq", K, dC)
            dBu = dBd - np.einsum("imq,mj->ijq", dK, disc.D) - np.einsum("im,mjq->ijq", K, dDd)
            blocks = [dAbar, dBu] + ([dK] if self.innovation else [])
            G_all = np.concatenate(blocks, axis=1).reshape(n * width, q)
            # ŷ_a(k) depends on C_aj through x̂_j(k) and on Dd_aj through u_j(k).
            G_c = dC.transpose(1, 0, 2).reshape(n, m * q)
            G_d = dDd.transpose(1, 0, 2).reshape(r, m * q)
        residuals, parts = [], []
        normal = triangle = None
        with np.errstate(over="ignore", invalid="ignore"):
            for index, (exp, x0) in enumerate(zip(self.batch, x0s, strict=True)):
                v = np.hstack([exp.u, exp.y])
                states = simulate_states(predictor, v, x0)
                predicted = states @ disc.C.T + exp.u @ disc.D.T
                residual = (predicted - exp.y) * self.weights
                residuals.append(residual.ravel())
                if G is None:
                    continue
                z_all = np.hstack([states, v if self.innovation else exp.u])
                rows = slice(self.states_at + index * n, self.states_at + (index + 1) * n)
                # Per sample the recursion costs n·q, the convolution m·n·width.
                direct = n * q > DIRECT_SENSITIVITY_SIZE or n * q < m * n * width
                per_sample = (n * q if direct else m * n * width) + m * q
                carried = self.basis[rows] if direct else np.zeros((n, n, width))
                reach = self.basis[rows]  # Ā^first ∂x0: the free response's start
                stretches = sample_stretches(exp.u.shape[0], per_sample)
                lifted = BLOCK_MAX if len(stretches) > 1 else None  # divides every stretch
                for first, last in stretches:
                    length, z = last - first, z_all[first:last]
                    if direct:
                        # ∂x̂ for every direction at once: ∂x̂(k+1) = Ā ∂x̂(k) + ∂Ā x̂(k) +
                        # ∂B̄ v(k), ∂x̂(0) = ∂x0; cheaper than per-entry sensitivities for big
                        # models.
                        forcing = z @ G_all.reshape(n, width, q).transpose(1, 0, 2).reshape(
                            width, -1
                        )
                        dstates, carried = _propagate(Abar, forcing.reshape(length, n, q), carried)
                        jac = np.matmul(disc.C, dstates).reshape(length * m, q)
                    else:
                        sens, carried = state_convolution_from(Abar, disc.C, z, carried, lifted)
                        jac = sens.reshape(length * m, n * width) @ G_all
                        jac += (
                            free_response_basis(StateSpace(Abar, Bbar, disc.C, disc.D), length)
                            @ reach
                        )
                        reach = np.linalg.matrix_power(Abar, length) @ reach
                    jac += (states[first:last] @ G_c).reshape(length * m, q)
                    jac += (exp.u[first:last] @ G_d).reshape(length * m, q)
                    jac *= np.tile(self.weights, length)[:, None]
                    r_part = residual[first:last].ravel()
                    if jacobian == "full":
                        parts.append(jac)
                    elif jacobian == "normal":
                        part = (jac.T @ jac, jac.T @ r_part)
                        normal = (
                            part if normal is None else (normal[0] + part[0], normal[1] + part[1])
                        )
                    else:
                        block = np.hstack([jac, r_part[:, None]])
                        if triangle is not None:
                            block = np.vstack([triangle, block])
                        triangle = scipy.linalg.qr(block, mode="r", check_finite=False)[0]
                        triangle = triangle[: q + 1]
        res = np.concatenate(residuals)
        if not np.all(np.isfinite(res)):
            return np.full(res.shape, np.inf), None
        if jacobian == "full":
            return res, np.vstack(parts)
        return res, normal if jacobian == "normal" else triangle

    def rms_errors(self, beta: np.ndarray) -> np.ndarray:
        """RMS simulation error per output (unweighted)."""
        res = self.evaluate(beta)[0].reshape(-1, self.m) / self.weights
        with np.errstate(over="ignore", invalid="ignore"):
            return np.sqrt(np.mean(res**2, axis=0))


def _levenberg_marquardt(
    problem: OutputErrorProblem,
    beta: np.ndarray,
    max_iterations: int,
    relative_decrease: float = RELATIVE_DECREASE,
) -> tuple[np.ndarray, int, bool]:
    """Minimise ‖residuals‖² from beta: Marquardt-scaled Levenberg–Marquardt steps.

    The normal equations are (P × P) with P the free parameters, far cheaper than an SVD of
    the (samples·outputs × P) Jacobian each step; the scaling by diag(JᵀJ) makes the step
    independent of parameter units (Marquardt, *SIAM J. Appl. Math.* 11, 1963).
    """
    res, (H, g) = problem.evaluate(beta, "normal")
    cost = float(res @ res)
    damping = 1e-3
    iterations, settled = 0, False
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported
        scale = np.maximum(np.diag(H), 1e-300)
        improved = False
        while damping < 1e12:
            try:
                step = -np.linalg.solve(H + damping * np.diag(scale), g)
            except np.linalg.LinAlgError:
                damping *= 10
                continue
            trial = beta + step
            new_res, _ = problem.evaluate(trial)
            with np.errstate(over="ignore", invalid="ignore"):
                new_cost = float(new_res @ new_res)  # inf for a diverging trial
            if new_cost < cost:
                improved = True
                break
            damping *= 10
        if not improved:
            settled = True
            break
        decrease = (cost - new_cost) / cost
        beta, cost = trial, new_cost
        damping = max(damping / 10, 1e-9)
        if decrease < relative_decrease:
            settled = True
            break
        res, (H, g) = problem.evaluate(beta, "normal")
    return beta, iterations, settled


def refine(
    model: StateSpace,
    dt: float,
    batch: Sequence[Experiment],
    *,
    output_coordinates: bool,
    estimate_d: bool,
    hold: str = "zoh",
    gain: np.ndarray | None = None,
    max_passes: int = MAX_PASSES,
    fixed: np.ndarray | None = None,
    initial_states: Sequence[np.ndarray] | None = None,
    relative_decrease: float = RELATIVE_DECREASE,
    block: int | None = None,
) -> Refinement:
    """Maximum-likelihood refinement of a continuous model (see module text).

    `model` is continuous (Ac, Bc, C, D). `output_coordinates`: C is the identity and stays
    fixed; otherwise C is refined too. D is refined only when `estimate_d`, else held.
    `gain`: None for output error; a starting K (n × m, discrete) for the prediction-error
    fit of the innovation form, which also models process noise (turbulence). `fixed`: the
    entries of [vec Ac, vec Bc] held at their values (a structured model). `initial_states`:
    each experiment's starting x(0), else the least-squares one of the simulation.
    `relative_decrease`: the cost's relative fall below which a pass ends. `block`: fit the
    means of the outputs over blocks of this many samples, exactly (agent.ident.lifted), the
    initial states those of the blocks' first samples; None: the samples.
    """
    if block is not None:
        batch = [Experiment(lift(e.u, block), block_means(e.y, block)) for e in batch]
    start = _discretize(model, dt, hold, block)
    if initial_states is None:
        x0s = [estimate_initial_state(start, e.u, e.y) for e in batch]
    else:
        x0s = [np.asarray(x, dtype=float) for x in initial_states]
    problem = OutputErrorProblem(
        model,
        dt,
        batch,
        x0s,
        free_c=not output_coordinates,
        free_d=estimate_d,
        hold=hold,
        gain=gain,
        fixed=fixed,
        block=block,
    )
    y_rms = np.sqrt(np.mean(np.vstack([e.y for e in batch]) ** 2, axis=0))
    floor = NOISE_FLOOR * np.where(y_rms > 0, y_rms, 1.0)
    beta = np.zeros(problem.basis.shape[1])
    sigma = np.maximum(problem.rms_errors(beta), floor)
    if not np.all(np.isfinite(sigma)):
        raise IdentificationFailed(
            "the starting model's simulation (or predictor) diverges: nothing to refine"
        )
    iterations, passes, settled = 0, 0, True
    for passes in range(1, max_passes + 1):  # noqa: B007 - reported
        problem.weights = 1.0 / sigma
        beta, used, settled = _levenberg_marquardt(problem, beta, MAX_ITERATIONS, relative_decrease)
        iterations += used
        new_sigma = np.maximum(problem.rms_errors(beta), floor)
        change = np.max(np.abs(new_sigma - sigma) / sigma)
        sigma = new_sigma
        if change < NOISE_TOLERANCE:
            break
    problem.weights = 1.0 / sigma
    final_res, triangle = problem.evaluate(beta, "triangle")
    start_res, _ = problem.evaluate(np.zeros_like(beta))
    refined, x0s = problem.unpack(beta)
    basis = problem.basis[: problem.matrix_size]
    return Refinement(
        gain=problem.gain(beta) if problem.innovation else None,
        continuous=refined,
        discrete=_discretize(refined, dt, hold, block),
        hold=hold,
        dt=dt * (block or 1),
        block=block,
        initial_states=tuple(x0s),
        noise_std=sigma,
        covariance=basis @ coloured_covariance(problem, beta, triangle[:, :-1]) @ basis.T,
        cost_initial=float(start_res @ start_res),
        cost=float(final_res @ final_res),
        iterations=iterations,
        passes=passes,
        converged=settled,
    )


def cramer_rao(
    model: StateSpace,
    dt: float,
    batch: Sequence[Experiment],
    noise_std: np.ndarray,
    *,
    output_coordinates: bool = True,
    estimate_d: bool = False,
    hold: str = "zoh",
    initial_states: Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """Cramér–Rao covariance of [vec Ac, vec Bc, vec C, vec D] at a known continuous model.

    The bound for white output noise of standard deviations `noise_std`, with the same free
    parameters as `refine` (initial states estimated too): what no unbiased estimator can
    beat on this input. Only the inputs of `batch` matter.
    """
    x0s = initial_states or [np.zeros(model.A.shape[0]) for _ in batch]
    problem = OutputErrorProblem(
        model, dt, batch, x0s, free_c=not output_coordinates, free_d=estimate_d, hold=hold
    )
    problem.weights = 1.0 / np.asarray(noise_std, dtype=float)
    _, triangle = problem.evaluate(np.zeros(problem.basis.shape[1]), "triangle")
    return _covariance(triangle[:, :-1], problem.basis[: problem.matrix_size])


def coloured_covariance(
    problem: OutputErrorProblem, beta: np.ndarray, triangle: np.ndarray
) -> np.ndarray:
    """The covariance of β corrected for coloured residuals (Morelli & Klein, "Accuracy of
    aerodynamic model parameters estimated from flight test data", *J. Guidance, Control, and
    Dynamics* 20(1), 1997; Klein & Morelli 2006, §6.5): M⁻¹ (Σ_t Σ_s J(t)ᵀ R(t − s) J(s)) M⁻¹,
    M = JᵀJ of the weighted Jacobian (`triangle`: its triangular factor) and R(k) the weighted
    residuals' autocorrelation. Unmodelled dynamics and turbulence leave residuals correlated
    in time, and the white-noise bound M⁻¹ then claims several times too little (a tenth of a
    second's correlation at 100 Hz counts each sample ten times). Computed in the frequency
    domain, J(ω)ᴴ Φ(ω) J(ω) summed over the bins with Φ the residuals' cross-spectral matrix
    (the periodogram averaged over COLOURED_BINS on either side): the time-domain sum with a
    lag window, positive semi-definite as it. White residuals give M back."""
    _, s, vt = np.linalg.svd(triangle, full_matrices=False)
    keep = s > s[0] * 1e-12 if s.size else s.astype(bool)
    inverse = (vt[keep].T / s[keep] ** 2) @ vt[keep]
    middle = np.zeros_like(inverse)
    m, q = problem.m, triangle.shape[1]
    residual, jacobian = problem.evaluate(beta, "full")
    start = 0
    for exp in problem.batch:
        length = exp.u.shape[0]
        step = max(4 * COLOURED_BINS, COLOURED_ENTRIES // (m * q))
        for first in range(0, length, step):
            last = min(length, first + step)
            rows = slice((start + first) * m, (start + last) * m)
            middle += _spectral_middle(
                residual[rows].reshape(-1, m), jacobian[rows].reshape(-1, m, q)
            )
        start += length
    return inverse @ middle @ inverse


def _spectral_middle(residual: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Σ_t Σ_s J(t)ᵀ R(t − s) J(s) of one stretch, residual (N, m), jacobian (N, m, q)."""
    N = residual.shape[0]
    rf = np.fft.rfft(residual, axis=0)  # (K, m)
    jf = np.fft.rfft(jacobian, axis=0)  # (K, m, q)
    outer = rf[:, :, None] * rf[:, None, :].conj() / N
    width = min(2 * COLOURED_BINS + 1, outer.shape[0])
    smooth = scipy.ndimage.uniform_filter1d(outer.real, width, axis=0, mode="nearest")
    smooth = smooth + 1j * scipy.ndimage.uniform_filter1d(outer.imag, width, axis=0, mode="nearest")
    # Each interior bin of the one-sided transform stands for two (Parseval).
    weight = np.full(outer.shape[0], 2.0)
    weight[0] = 1.0
    if N % 2 == 0:
        weight[-1] = 1.0
    values, vectors = np.linalg.eigh(smooth)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]  # Φ = root rootᴴ
    g = root.conj().transpose(0, 2, 1) @ jf * np.sqrt(weight / N)[:, None, None]
    g = g.reshape(-1, jf.shape[2])
    return (g.conj().T @ g).real


def _covariance(jac: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Cramér–Rao covariance of the model matrices: basis (JᵀJ)⁻¹ basisᵀ, by SVD of J (or of
    its triangular factor R, which has J's singular values and right vectors)."""
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    keep = s > s[0] * 1e-12 if s.size else s.astype(bool)
    inv = (vt[keep].T / s[keep] ** 2) @ vt[keep]
    return basis @ inv @ basis.T


def dof_factor(g: np.ndarray, spread) -> float:
    """How much wider a sandwich standard error must be for the few frequency bins that carry
    the contrast g (over the covariance's vector) to be honest: √(ν/(ν − 2)), ν the
    Satterthwaite degrees of freedom of its variance estimate, ν = (Σ q_k)² / Σ q_k², q_k bin
    k's share of that variance by design (`agent.ident.aircraft.fit.sandwich`), ν at least
    DOF_FLOOR (1 where `spread` is empty).

    The sandwich estimates a contrast's variance from the residuals of the bins that
    determine it; a phugoid or a spiral lies in a handful of a minute's bins, so its estimate
    has the variance of a χ² of few degrees of freedom, and the error over it is t-like, the
    rms of its z-scores √(ν/(ν − 2)) rather than 1 (Bell & McCaffrey, *Survey Methodology*
    28(2), 2002, §3, the Satterthwaite approximation for their CR2 sandwich; Imbens & Kolesár,
    *Review of Economics and Statistics* 98(4), 2016). A mode many bins carry (ν in the tens
    or hundreds: a short period, a roll mode) is left as it was."""
    shares = [((G @ g[pos]) ** 2).sum(axis=1) for G, pos in spread]
    if not shares:
        return 1.0
    q = np.concatenate(shares)[:, None]
    return float(_widening(q)[0])


def entry_dof_factors(spread, size: int) -> np.ndarray:
    """`dof_factor` of each entry of the covariance's vector alone (1 where `spread` has no
    column of it)."""
    factors = np.ones(size)
    for G, pos in spread:
        q = (G * G).sum(axis=1)  # (bins, columns): each bin's share of each entry's variance
        factors[pos] = _widening(q)
    return factors


def _widening(q: np.ndarray) -> np.ndarray:
    """√(ν/(ν − 2)) per column of q (bins, columns), each bin's share of that column's
    variance; ν = (Σ q)² / Σ q², at least DOF_FLOOR; 1 for a column no bin carries (a fixed
    entry's, all zero)."""
    total, squares = q.sum(axis=0), (q * q).sum(axis=0)
    out = np.ones(q.shape[1])
    carried = (squares > 0) & (total > 0)
    nu = np.maximum(total[carried] ** 2 / squares[carried], DOF_FLOOR)
    out[carried] = np.sqrt(nu / (nu - 2.0))
    return out


def eigenvalue_std(Ac: np.ndarray, covariance_A: np.ndarray, spread=()) -> list[EigenvalueStd]:
    """First-order uncertainty of every eigenvalue of Ac given the covariance of vec(Ac), each
    widened for the few bins that carry it where `spread` (`Refinement.spread_of_a`) says.

    ∂λ/∂A_ij = w̄_i v_j / (wᴴ v) for right and left eigenvectors v, w (Wilkinson, *The
    Algebraic Eigenvalue Problem*, 1965, §2.8). Order follows `np.linalg.eig(Ac)`.
    """
    lam, V = np.linalg.eig(Ac)
    W = np.linalg.inv(V).conj().T  # columns: left eigenvectors with wᴴ v = 1
    out = []
    for k in range(lam.size):
        grad = np.outer(W[:, k].conj(), V[:, k]).ravel()
        s = complex(lam[k])
        mag = abs(s)
        g_re, g_im = grad.real, grad.imag
        # ∂|s| = (Re s ∂Re s + Im s ∂Im s)/|s|;  ζ = −Re s/|s|
        g_mag = (s.real * g_re + s.imag * g_im) / mag if mag > 0 else g_re
        g_zeta = -(g_re * mag - s.real * g_mag) / mag**2 if mag > 0 else 0 * g_re

        def std(g: np.ndarray) -> float:
            return float(np.sqrt(max(g @ covariance_A @ g, 0.0))) * dof_factor(g, spread)

        out.append(
            EigenvalueStd(real=std(g_re), imag=std(g_im), frequency=std(g_mag), damping=std(g_zeta))
        )
    return out


def simulate_refined(refinement: Refinement, batch: Sequence[Experiment]) -> list[np.ndarray]:
    """The refined model's simulated outputs per experiment, from its refined initial states
    (the blocks' means where it fitted them)."""
    block = refinement.block
    return [
        simulate(refinement.discrete, e.u if block is None else lift(e.u, block), x0)
        for e, x0 in zip(batch, refinement.initial_states, strict=True)
    ]


def with_uncertainty(modes: Sequence[Mode], refinement: Refinement) -> list[Mode]:
    """Attach the Cramér–Rao 1-σ of each mode's eigenvalue (nearest eigenvalue of Ac)."""
    lam = np.linalg.eigvals(refinement.continuous.A)
    stds = eigenvalue_std(
        refinement.continuous.A, refinement.covariance_of_a(), refinement.spread_of_a()
    )
    out = []
    for mode in modes:
        k = int(np.argmin(np.abs(lam - mode.eigenvalue)))
        out.append(replace(mode, uncertainty=stds[k]))
    return out


def second_order_std(order: SecondOrder, refinement: Refinement) -> SecondOrder:
    """`order` with the Cramér–Rao 1-σ of its ωn and ζ: first order in the covariance of
    vec(Ac), through the sum p1 = s1 + s2 and product p0 = s1 s2 of its poles (∂p1 = ∂s1 + ∂s2,
    ∂p0 = s2 ∂s1 + s1 ∂s2, each ∂s as in `eigenvalue_std`), ωn = √p0, ζ = −p1 / 2ωn. The sum
    and product are smooth where the two poles meet, which the poles are not."""
    A = refinement.continuous.A
    lam, V = np.linalg.eig(A)
    W = np.linalg.inv(V).conj().T
    k1 = int(np.argmin(np.abs(lam - order.poles[0])))
    k2 = int(np.argmin(np.where(np.arange(lam.size) == k1, np.inf, np.abs(lam - order.poles[1]))))
    g1, g2 = (np.outer(W[:, k].conj(), V[:, k]).ravel() for k in (k1, k2))
    s1, s2 = lam[k1], lam[k2]
    wn, p1 = order.frequency, float((s1 + s2).real)
    d_wn = ((s2 * g1 + s1 * g2) / (2 * wn)).real
    d_zeta = (-(g1 + g2) / (2 * wn)).real + p1 / (2 * wn**2) * d_wn
    covariance, spread = refinement.covariance_of_a(), refinement.spread_of_a()

    def std(g: np.ndarray) -> float:
        return float(np.sqrt(max(g @ covariance @ g, 0.0))) * dof_factor(g, spread)

    return replace(order, frequency_std=std(d_wn), damping_std=std(d_zeta))
