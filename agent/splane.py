"""The s-plane's geometry, shared by the report's figure and the console's view.

Aircraft modes span three decades — a spiral at 0.01 rad/s, a phugoid at 0.3, a roll at 12 —
so on linear axes the slow ones sit on the origin. The radius is drawn on a log scale instead,
r = log10(1 + |s| / RADIUS_REF), and the angle kept: lines of constant damping ζ (rays from the
origin) stay straight and circles of constant natural frequency ωn stay circles, so both grids
read as on any s-plane, and a mode's ζ is read off as usual. Near the origin the scale is
linear.
"""

from __future__ import annotations

import numpy as np

# |s| (rad/s) below which the radius is about linear.
RADIUS_REF = 0.01
# The grid: natural frequencies (rad/s) and damping ratios.
OMEGA_GRID = (0.01, 0.1, 1.0, 10.0, 100.0)
ZETA_GRID = (0.1, 0.2, 0.4, 0.7, 0.9)


def warp(s) -> np.ndarray:
    """s (rad/s, complex) → the drawn plane: radius log10(1 + |s|/RADIUS_REF), same angle."""
    s = np.asarray(s, dtype=complex)
    radius = np.abs(s)
    scale = np.log10(1.0 + radius / RADIUS_REF) / np.where(radius > 0, radius, 1.0)
    return s * scale


def warped_radius(omega: float) -> float:
    return float(np.log10(1.0 + omega / RADIUS_REF))


def ellipse(s: complex, std: tuple[float, float], k: float = 2.0, points: int = 48) -> np.ndarray:
    """The k-σ ellipse of an eigenvalue with independent real and imaginary standard errors,
    in s (complex points; `warp` them to draw)."""
    t = np.linspace(0.0, 2.0 * np.pi, points)
    return s + k * (std[0] * np.cos(t) + 1j * std[1] * np.sin(t))


def zeta_ray(zeta: float, radius: float, upper: bool = True) -> complex:
    """The end, at |s| = radius, of the ray of damping ζ (upper or lower half plane)."""
    angle = np.pi - np.arccos(zeta)
    return complex(radius * np.cos(angle), radius * np.sin(angle) * (1 if upper else -1))
