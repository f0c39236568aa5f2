"""The Cramér–Rao bound of a given model on a record: how closely any unbiased estimator of the
whole-aircraft model's structure could know that model's parameters from this record, were
the model the truth. The benchmark computes it for the validated truth, to tell a target the
record cannot meet (the bound wider than the target) from one the method misses.

The noise is what the given model leaves unexplained in the record: the sensors' noise, the
turbulence the record does not measure, the nonlinearity. Its spectrum is estimated from the
model's own residuals, with the parameters the model does not give refitted first: the
transients, the gains of the known inputs (gusts, sideslip drag, the α products) and the
engine's lags, whose form in the truth is not the fit's (`nuisance`).

The bound is the frequency-domain (Whittle) one for Gaussian noise of a known spectrum
(Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2012, §7.2): the
bins independent, bin k's residual complex Gaussian with the outputs' cross-spectral matrix
Φ_k, and the information M = 2 Re Σ_k J_kᴴ Φ_k⁻¹ J_k, J_k = ∂X_k/∂θ. Φ_k is the residuals'
outer product averaged over the `fit.SMOOTH_BINS` nearest bins on either side, as the fit's
weights are, with the cross terms: noise that moves several outputs together (a gust) is
worth more to an estimator that knows it does. Its inverse is scaled by (N − n)/N, N the bins
averaged and n the outputs, which makes it unbiased (the inverse of a complex Wishart matrix).
"""

from __future__ import annotations

import numpy as np

from agent.ident.aircraft.fit import AxisFit, bin_sigma, minimise, normal_inverse, smooth_bins
from agent.ident.aircraft.model import Fitted
from agent.ident.aircraft.problem import AxisProblem

# Passes of the nuisance parameters' refit, each with the weights of the last one's residuals.
NUISANCE_PASSES = 3


def bound(fitted: Fitted, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The Cramér–Rao covariance of vec(A) (m × m, row-major, over the record's outputs) at the
    model ẋ = A x + B u: A (m × m) and B (m × r) in the record's output and input columns and
    units, a NaN column of B for an input the model does not give (its gains are then
    nuisance parameters, as the throttle's through the fit's engine lags always are). Entries
    the fit holds fixed (the kinematics) or leaves out (couplings the data did not show) have
    no variance; the two axes' fits are independent."""
    m = A.shape[0]
    width = fitted.sp.U.shape[1]
    index = np.arange(m * m).reshape(m, m)
    out = np.zeros((m * m, m * m))
    for fit in fitted.fits:
        problem, theta, given = _at_model(fitted, fit, A, B)
        theta = nuisance(problem, theta, ~given, fit.bin_std)
        cov = whittle(problem, theta)
        n, r, st = problem.n, problem.r, list(fit.states)
        pos, keep = [], []
        for a in range(n):
            for b in range(n):
                pos.append(index[st[a], st[b]])
                keep.append(a * n + b)
            for c, j in enumerate(fit.inputs):
                if j >= width:  # another axis's state: its gain is an entry of A
                    pos.append(index[st[a], j - width])
                    keep.append(n * n + a * r + c)
        out[np.ix_(pos, pos)] = cov[np.ix_(keep, keep)]
    return out


def _at_model(fitted: Fitted, fit: AxisFit, A: np.ndarray, B: np.ndarray):
    """The axis's problem as fitted, its parameters with the model's A and B put in where
    they are free, and which free parameters the model gives."""
    width = fitted.sp.U.shape[1]
    lagged = tuple(fit.lags)
    problem = AxisProblem(
        fitted.augmented,
        states=fit.states,
        inputs=fit.inputs,
        lagged=lagged,
        experiments=len(fitted.batch),
        controls=fit.controls,
        powers=fit.lag_powers,
    )
    taus = np.array([fit.lags[j] for j in lagged])
    st = list(fit.states)
    A_fit, B_fit = fit.A.copy(), fit.B.copy()
    free_A, free_B = ~problem.fixed_A, ~problem.fixed_B
    A_fit[free_A] = A[np.ix_(st, st)][free_A]
    given_B = np.zeros_like(free_B)
    for c, j in enumerate(fit.inputs):
        if j >= width:
            column = A[st, j - width]
        elif j < B.shape[1] and j not in fit.lags and np.all(np.isfinite(B[:, j])):
            column = B[st, j]
        else:
            continue
        B_fit[free_B[:, c], c] = column[free_B[:, c]]
        given_B[:, c] = free_B[:, c]
    theta = problem.pack(A_fit, B_fit, taus, fit.transients)
    n, r = problem.n, problem.r
    given = np.zeros(problem.size, dtype=bool)
    given[: n * n] = free_A.ravel()
    given[n * n : n * n + n * r] = given_B.ravel()
    return problem, theta, given


def nuisance(
    problem: AxisProblem, theta: np.ndarray, which: np.ndarray, sigma: np.ndarray
) -> np.ndarray:
    """`theta` with the free parameters in `which` refitted (the others held), reweighted from
    the residuals between NUISANCE_PASSES passes."""
    held = replace_free(problem, problem.free & which)
    for _ in range(NUISANCE_PASSES):
        theta, _, _ = minimise(held, theta, sigma)
        X, _ = problem.response(theta)
        sigma = bin_sigma(problem.Y - X, problem.s)
    return theta


def replace_free(problem: AxisProblem, free: np.ndarray) -> AxisProblem:
    """A shallow copy of `problem` whose free parameters are `free`."""
    copy = object.__new__(AxisProblem)
    copy.__dict__.update(problem.__dict__)
    copy.free = free
    return copy


def whittle(problem: AxisProblem, theta: np.ndarray) -> np.ndarray:
    """The Whittle bound's covariance of θ (zero for fixed parameters) at `theta`, the noise's
    cross-spectra from its residuals (module docstring)."""
    X, J = problem.response(theta, jacobian=True)
    R = problem.Y - X
    n = R.shape[1]
    outer = R[:, :, None] * R[:, None, :].conj()  # (F, n, n)
    real, averaged = smooth_bins(outer.real, problem.s)
    imag, _ = smooth_bins(outer.imag, problem.s)
    smooth = real + 1j * imag
    # A relative floor keeps an output the model explains to the last digits invertible.
    scale = np.einsum("fii->fi", smooth).real.max(axis=0)
    smooth += np.eye(n) * 1e-12 * max(float(scale.max()), 1e-300)
    inverse = np.linalg.inv(smooth) * max(averaged - n, 1) / averaged
    free = problem.free
    Jf = J[:, :, free]
    weighted = inverse @ Jf  # (F, n, p)
    M = 2 * (Jf.conj().reshape(-1, Jf.shape[2]).T @ weighted.reshape(-1, Jf.shape[2])).real
    out = np.zeros((theta.size, theta.size))
    out[np.ix_(free, free)] = normal_inverse(M)  # a direction the record does not determine kept
    return out
