"""Rigid-body kinematics and gravity, known exactly (no aerodynamic parameter), for the eight
states in KINEMATIC_STATES order: their linear part about the trim is what the model's A
holds for θ and φ, and what is left (the remainder) is a known forcing of each state's
equation (Stevens & Lewis, *Aircraft Control and Simulation*, §2.4)."""

from __future__ import annotations

import numpy as np

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
