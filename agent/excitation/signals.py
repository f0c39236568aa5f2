"""Excitation signals as pure numpy arrays (thesis §4.4.5).

Multisines follow eq. 4.30 with Schroeder's phases (eq. 4.34; Schroeder, "Synthesis of
low-peak-factor signals and binary sequences with low autocorrelation", IEEE Trans. Inf.
Theory 16, 1970), and the peak factors of eq. 4.31–4.33.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# The thesis's table 6.4 allocation: harmonics of the base period per surface, mutually
# exclusive so the surfaces are orthogonal over a whole period.
THESIS_HARMONICS = {
    "aileron": (3, 6, 9, 12),
    "rudder": (5, 10, 15, 20),
    "elevator": (7, 14, 21, 28),
}


def schroeder_phases(count: int) -> np.ndarray:
    """φ_1 = 0, φ_k = φ_(k−1) − π k²/M for k = 2 … M (eq. 4.34, equal amplitudes)."""
    phases = np.zeros(count)
    for k in range(2, count + 1):
        phases[k - 1] = phases[k - 2] - np.pi * k**2 / count
    return phases


def multisine(
    harmonics: Sequence[int],
    period: float,
    dt: float,
    duration: float,
    amplitude: float,
    phases: Sequence[float] | None = None,
) -> np.ndarray:
    """Σ cos(2π k t / T + φ_k) over the given harmonics k, scaled to peak `amplitude` (eq. 4.30).

    Equal amplitudes per harmonic; Schroeder phases unless given. The signal repeats every
    `period` seconds, so any whole number of periods is free of spectral leakage.
    """
    k = np.asarray(harmonics, dtype=float)
    phi = schroeder_phases(k.size) if phases is None else np.asarray(phases, dtype=float)
    t = np.arange(round(duration / dt)) * dt
    wave = np.cos(2 * np.pi * np.outer(t, k) / period + phi).sum(axis=1)
    # Scale by the peak over one whole period, so a short record keeps the designed amplitude.
    one = np.cos(2 * np.pi * np.outer(np.arange(round(period / dt)) * dt, k) / period + phi)
    return amplitude * wave / np.max(np.abs(one.sum(axis=1)))


def peak_factor(u: np.ndarray) -> float:
    """PF = ((max − min)/2)/rms (eq. 4.31–4.32); a single sine has √2."""
    u = np.asarray(u, dtype=float)
    return float((u.max() - u.min()) / 2 / np.sqrt(np.mean(u**2)))


def relative_peak_factor(u: np.ndarray) -> float:
    """RPF = PF/√2 (eq. 4.33): 1 for a single sine."""
    return peak_factor(u) / np.sqrt(2)


def doublet(dt: float, pulse: float, amplitude: float, lead: float = 0.0, tail: float = 0.0):
    """+A for `pulse` s, −A for `pulse` s, with `lead` and `tail` seconds of zero around it."""
    n_lead, n_pulse, n_tail = round(lead / dt), round(pulse / dt), round(tail / dt)
    return np.concatenate(
        [
            np.zeros(n_lead),
            np.full(n_pulse, amplitude),
            np.full(n_pulse, -amplitude),
            np.zeros(n_tail),
        ]
    )
