"""One axis's output-error problem in the frequency domain: its parameters, its model's
transforms and their exact Jacobian."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from agent.ident.aircraft.transforms import Transforms, excited

# Engine spin-up between throttle and thrust, as equal first-order lags of one estimated time
# constant. How many, the data say (`agent.ident.aircraft.model`): ENGINE_ORDERS are tried and
# the Akaike criterion picks one — none (a thrust that follows at once), one (a turbine's
# spool, a propeller's speed), two (a piston's manifold pressure and engine speed; JSBSim's
# piston engines show poles at 1–3 and 1–10 1/s). Two separate time constants are not
# identifiable apart from each other in a minute of data (the fit wanders along τ1 ↔ τ2).
# THROTTLE_LAGS is the order fitted first and the one a lagged input has unless told.
ENGINE_ORDERS = (0, 1, 2)
THROTTLE_LAGS = 2
LAG_START_S = 0.3


class AxisProblem:
    """The output-error problem of one model: parameters θ = [vec A, vec B, τ, Re d, Im d].

    Where the kinematics are known (Transforms.kinematics), what holds no aerodynamic parameter is
    fixed rather than fitted: the rows of θ and φ (pure kinematics: θ̇ = q cos φ − r sin φ,
    φ̇ = p + tan θ (q sin φ + r cos φ); their inputs' gains are zero) and the columns of θ and
    φ (no force depends on the attitude; gravity does, through the kinematics). Left free,
    output error used them to absorb what it could not model (θ̇ in q with a gain far from 1,
    q in the airspeed's equation). The kinematics' linear terms in the other axis's states
    join the known forcing."""

    def __init__(
        self,
        sp: Transforms,
        *,
        states: Sequence[int],
        inputs: Sequence[int],
        lagged: Sequence[int],
        experiments: int,
        controls: Sequence[int] = (),
        powers: Mapping[int, int] | None = None,
        zeros: Sequence[tuple[str, int, int]] = (),
    ):
        """`zeros`: the entries fixed at zero (("A" or "B", row, column)), a model structure
        chosen by the data (agent.ident.aircraft.fit.selected)."""
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
        for matrix, i, j in zeros:
            if matrix == "A":
                self.fixed_A[i, j], self.A0[i, j] = True, 0.0
            else:
                self.fixed_B[i, j] = True
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
