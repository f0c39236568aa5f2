"""Excitation signals as pure numpy arrays (thesis §4.4.5), in units of the surface (degrees
or percent from trim), sampled every `dt` seconds from t = 0.

Multisines follow eq. 4.30 with Schroeder's phases (eq. 4.34; Schroeder, "Synthesis of
low-peak-factor signals and binary sequences with low autocorrelation", IEEE Trans. Inf.
Theory 16, 1970) or phases optimised for a low peak factor, and the peak factors of
eq. 4.31–4.33. Harmonics are allocated across surfaces so that the surfaces are mutually
orthogonal over a whole period (Morelli, "Multiple input design for real-time parameter
estimation in the frequency domain", IFAC SYSID 2003).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from scipy.optimize import minimize

# The thesis's table 6.4 allocation: harmonics of the base period per surface, mutually
# exclusive so the surfaces are orthogonal over a whole period.
THESIS_HARMONICS = {
    "aileron": (3, 6, 9, 12),
    "rudder": (5, 10, 15, 20),
    "elevator": (7, 14, 21, 28),
}
# Pulse patterns for `pulses`, in units of the pulse length: the doublet and the 3-2-1-1.
DOUBLET = (1, -1)
THREE_TWO_ONE_ONE = (3, -2, 1, -1)

# Phase optimisation grid: samples per period of the highest harmonic. Fine enough that the
# optimised peak holds at any command rate (the peak between grid points is < 0.1 % higher).
_GRID_PER_CYCLE = 64
# Clipping passes of the phase optimiser per start; the RPF of 4–25 harmonics settles within
# ~100.
_PHASE_PASSES = 200
# Each pass clips the signal to this fraction of its peak-to-peak range.
_CLIP = 0.9
# The clipped phases are then polished by minimising the waveform's p-norm for growing p (a
# smooth stand-in for the peak), and the best of _PHASE_STARTS starts is kept: Schroeder's
# phases and seeded random ones. On the full preset's 25-harmonic surfaces this takes the RPF
# from 1.25–1.26 (clipping alone) to the values `sysid excite --preset full --json` prints.
_P_NORMS = (8, 32, 128)
_PHASE_STARTS = 4
_PHASE_SEED = 20031  # fixed, so the ground and the aircraft compute the same phases


def _samples(duration: float, dt: float) -> int:
    return max(0, round(duration / dt))


def schroeder_phases(count: int) -> np.ndarray:
    """φ_1 = 0, φ_k = φ_(k−1) − π k²/M for k = 2 … M (eq. 4.34, equal amplitudes)."""
    phases = np.zeros(count)
    for k in range(2, count + 1):
        phases[k - 1] = phases[k - 2] - np.pi * k**2 / count
    return phases


def _one_period(
    harmonics: np.ndarray, phases: np.ndarray, gains: np.ndarray | float = 1.0
) -> np.ndarray:
    """Σ g_k cos(2πkτ + φ_k) on _GRID_PER_CYCLE points per cycle of the highest harmonic."""
    k = np.asarray(harmonics).astype(int)
    n = _GRID_PER_CYCLE * int(k.max())
    spectrum = np.zeros(n // 2 + 1, dtype=complex)
    spectrum[k] = n / 2 * np.asarray(gains) * np.exp(1j * np.asarray(phases))
    return np.fft.irfft(spectrum, n)


def _clipped(k: np.ndarray, phases: np.ndarray) -> np.ndarray:
    n = _GRID_PER_CYCLE * int(k.max())
    best, best_phases = np.inf, phases
    for _ in range(_PHASE_PASSES):
        u = _one_period(k, phases)
        lo, hi = u.min(), u.max()
        if hi - lo < best:
            best, best_phases = hi - lo, phases
        mid, half = (hi + lo) / 2, _CLIP * (hi - lo) / 2
        phases = np.angle(np.fft.rfft(np.clip(u, mid - half, mid + half), n)[k])
    return best_phases


def _polished(k: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """Minimise (mean u^p)^(1/p) over the phases, p = _P_NORMS in turn (L-BFGS, analytic
    gradient: ∂u/∂φ_k = −sin(2πkτ + φ_k), summed against u^(p−1) by one FFT)."""
    n = _GRID_PER_CYCLE * int(k.max())
    scale = np.sqrt(k.size / 2)  # the rms, so u^p stays in range
    for p in _P_NORMS:

        def cost(x: np.ndarray, p: int = p) -> tuple[float, np.ndarray]:
            u = _one_period(k, x) / scale
            mean = np.mean(u**p)
            weights = np.fft.rfft(u ** (p - 1), n)[k]
            grad = -np.imag(np.exp(1j * x) * np.conj(weights)) * p / (n * scale)
            return float(np.log(mean) / p), grad / (p * mean)

        phases = minimize(cost, phases, jac=True, method="L-BFGS-B").x
    return phases


def _peak_to_peak(k: np.ndarray, phases: np.ndarray) -> float:
    u = _one_period(k, phases)
    return float(u.max() - u.min())


@lru_cache(maxsize=64)
def _optimised(harmonics: tuple[int, ...]) -> tuple[float, ...]:
    k = np.asarray(harmonics)
    rng = np.random.default_rng(_PHASE_SEED)
    starts = [schroeder_phases(k.size)]
    starts += [rng.uniform(0, 2 * np.pi, k.size) for _ in range(_PHASE_STARTS - 1)]
    clipped = [_clipped(k, s) for s in starts]
    candidates = clipped + [_polished(k, phases) for phases in clipped]
    best = min(candidates, key=lambda phases: _peak_to_peak(k, phases))
    return tuple(float(p) for p in np.angle(np.exp(1j * best)))


def low_peak_phases(harmonics: Sequence[int]) -> np.ndarray:
    """Phases of equal-amplitude harmonics with a low relative peak factor.

    From each of a few starts (Schroeder's phases, seeded random ones), alternates clipping
    the waveform to 90 % of its peak-to-peak range with restoring the flat amplitude spectrum
    (the clipping algorithm of Van der Ouderaa, Schoukens and Renneboog, "Peak factor
    minimization using a time-frequency domain swapping algorithm", IEEE Trans. Instrum.
    Meas. 37, 1988), then also minimises the waveform's p-norm for growing p (a smooth
    approximation of its peak, as in Guillaume et al., "Crest-factor minimization using
    nonlinear Chebyshev approximation methods", IEEE Trans. Instrum. Meas. 40, 1991), and
    keeps the lowest peak of all. Deterministic, so a plan previewed on the ground plays the same
    onboard. Four harmonics reach RPF ≈ 1.01 (Schroeder: 1.19); 25 reach 1.0–1.12.
    """
    k = tuple(int(h) for h in harmonics)
    if not k or min(k) < 1 or len(set(k)) != len(k):
        raise ValueError(f"harmonics must be distinct integers ≥ 1, got {list(harmonics)}")
    return np.array(_optimised(k))


def forget_phases() -> None:
    """Forget the phases optimised so far (each set of harmonics is optimised once per process
    and kept), so the next `low_peak_phases` computes them afresh: for a test or benchmark
    that needs the optimisation's CPU time."""
    _optimised.cache_clear()


def zero_start(
    harmonics: Sequence[int], phases: Sequence[float], gains: Sequence[float] | None = None
) -> np.ndarray:
    """The same multisine delayed so it starts at a zero crossing: phases φ_k + k·θ.

    A time shift leaves the amplitude spectrum, the peak factor and the orthogonality to other
    harmonics unchanged, and whole periods then start and end at trim instead of jumping to
    Σ g_k cos φ_k. Of the zero crossings, the one with the gentlest slope is taken; `gains`
    (default 1) are the lines' amplitudes (a shaped multisine crosses zero elsewhere).
    """
    k = np.asarray(harmonics, dtype=float)
    phi = np.asarray(phases, dtype=float)
    g = np.ones(k.size) if gains is None else np.asarray(gains, dtype=float)
    u = _one_period(k, phi, g)
    n = u.size
    up = np.flatnonzero(np.sign(u) != np.sign(np.roll(u, -1)))
    slope = np.abs(np.roll(u, -1)[up] - u[up])
    i = int(up[np.argmin(slope)])
    theta = 2 * np.pi * (i + u[i] / (u[i] - u[(i + 1) % n])) / n
    for _ in range(3):  # Newton on the exact waveform: u(θ) = Σ g cos(kθ + φ)
        value = (g * np.cos(k * theta + phi)).sum()
        theta -= value / -(g * k * np.sin(k * theta + phi)).sum()
    return phi + k * theta


def multisine(
    harmonics: Sequence[int],
    period: float,
    dt: float,
    duration: float,
    amplitude: float,
    phases: Sequence[float] | None = None,
    gains: Sequence[float] | None = None,
) -> np.ndarray:
    """Σ g_k cos(2π k t / T + φ_k) over the given harmonics k (eq. 4.30), scaled so that the
    equal-amplitude signal (every g_k = 1) peaks at `amplitude`.

    Schroeder phases unless given; `gains` g_k (default 1) shape the spectrum (`shaped`). The
    signal repeats every `period` seconds, so any whole number of periods is free of spectral
    leakage.
    """
    k = np.asarray(harmonics, dtype=float)
    phi = schroeder_phases(k.size) if phases is None else np.asarray(phases, dtype=float)
    g = np.ones(k.size) if gains is None else np.asarray(gains, dtype=float)
    t = np.arange(_samples(duration, dt)) * dt
    wave = (g * np.cos(2 * np.pi * np.outer(t, k) / period + phi)).sum(axis=1)
    # Scale by the peak over one whole period, so a short record keeps the designed amplitude.
    one = np.cos(2 * np.pi * np.outer(np.arange(round(period / dt)) * dt, k) / period + phi)
    return amplitude * wave / np.max(np.abs(one.sum(axis=1)))


def shaped(shape: Sequence[tuple[float, float]], hz: np.ndarray) -> np.ndarray:
    """The gain of a spectral shape at each frequency: `shape` is breakpoints (Hz, gain) in
    ascending frequency, interpolated linearly in log-frequency and held beyond its ends; an
    empty shape is 1 everywhere.

    A flight-test engineer sizes a sweep's or a multisine's amplitude to the response it causes
    at each frequency: a glider's elevator at 0.1 Hz swings the airspeed where at 2 Hz it only
    moves α (docs/excitation.md, *Sizing*, step 4)."""
    hz = np.asarray(hz, dtype=float)
    if not shape:
        return np.ones_like(hz)
    at = np.log([f for f, _ in shape])
    return np.interp(np.log(hz), at, [g for _, g in shape])


def allocate_harmonics(
    surfaces: Sequence[str], period: float, band_hz: tuple[float, float]
) -> dict[str, tuple[int, ...]]:
    """Interleave the harmonics of 1/period inside the band across the surfaces.

    Harmonic k goes to surface (k − k_min) mod S, so every surface spans the whole band and no
    two share a frequency: they are orthogonal over any whole number of periods.
    """
    lo, hi = band_hz
    if not surfaces or len(set(surfaces)) != len(surfaces):
        raise ValueError("allocate_harmonics needs distinct surface names")
    if period <= 0 or not 0 <= lo < hi:
        raise ValueError(f"need period > 0 and 0 ≤ low < high, got {period}, {band_hz}")
    k_min, k_max = max(1, int(np.ceil(lo * period - 1e-9))), int(np.floor(hi * period + 1e-9))
    harmonics = list(range(k_min, k_max + 1))
    if len(harmonics) < len(surfaces):
        raise ValueError(
            f"{len(harmonics)} harmonics of a {period:g} s period lie in {lo:g}–{hi:g} Hz, "
            f"fewer than the {len(surfaces)} surfaces: lengthen the period or widen the band"
        )
    count = len(surfaces)
    return {s: tuple(harmonics[i::count]) for i, s in enumerate(surfaces)}


def peak_factor(u: np.ndarray) -> float:
    """PF = ((max − min)/2)/rms (eq. 4.31–4.32); a single sine has √2."""
    u = np.asarray(u, dtype=float)
    return float((u.max() - u.min()) / 2 / np.sqrt(np.mean(u**2)))


def relative_peak_factor(u: np.ndarray) -> float:
    """RPF = PF/√2 (eq. 4.33): 1 for a single sine."""
    return peak_factor(u) / np.sqrt(2)


def doublet(dt: float, pulse: float, amplitude: float, lead: float = 0.0, tail: float = 0.0):
    """+A for `pulse` s, −A for `pulse` s, with `lead` and `tail` seconds of zero around it."""
    return np.concatenate(
        [
            np.zeros(_samples(lead, dt)),
            pulses(dt, pulse, amplitude, DOUBLET),
            np.zeros(_samples(tail, dt)),
        ]
    )


def pulses(dt: float, unit: float, amplitude: float, pattern: Sequence[int]) -> np.ndarray:
    """Alternating pulses of the given lengths in units of `unit` s: (1, −1) is a doublet.

    The sign of each entry is the pulse's sign and its magnitude the length in units; each
    pulse is rounded on its own cumulative edge so the total is round(Σ|n|·unit/dt) samples.
    """
    edges = np.round(np.cumsum([0] + [abs(n) for n in pattern]) * unit / dt).astype(int)
    out = np.zeros(edges[-1])
    for (a, b), n in zip(itertools.pairwise(edges), pattern, strict=True):
        out[a:b] = np.sign(n) * amplitude
    return out


def three_two_one_one(dt: float, unit: float, amplitude: float) -> np.ndarray:
    """3-2-1-1: +A for 3Δt, −A for 2Δt, +A for Δt, −A for Δt (thesis §4.4.5.1); Δt = `unit`.

    The 2Δt pulse is aimed at the mode of interest (period ≈ 4Δt … 5Δt); the others widen the
    excited band.
    """
    return pulses(dt, unit, amplitude, THREE_TWO_ONE_ONE)


def sweep_frequency(
    t: np.ndarray, f_start: float, f_end: float, duration: float, law: str = "linear"
) -> np.ndarray:
    """Instantaneous frequency (Hz) of the sweep at times t within [0, duration]."""
    tau = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)
    if law == "linear":
        return f_start + (f_end - f_start) * tau
    if law == "log":
        return f_start * (f_end / f_start) ** tau
    raise ValueError(f'sweep law must be "linear" or "log", got {law!r}')


def sweep(
    dt: float,
    f_start: float,
    f_end: float,
    duration: float,
    amplitude: float,
    law: str = "linear",
    fade: float = 0.0,
    dwell_cycles: float = 0.0,
    shape: Sequence[tuple[float, float]] = (),
) -> np.ndarray:
    """A sine sweep A·g(f)·sin(2π∫f dt) from f_start to f_end in `duration` s.

    law "linear": f = f₀ + (f₁ − f₀)t/T; "log": f = f₀(f₁/f₀)^(t/T) (ArduPilot's SystemID
    chirp law). `dwell_cycles` whole cycles at f₀ come first; the whole signal fades in and
    out over `fade` s with a raised cosine, so it starts and ends at trim with zero slope.
    g(f) is `shape`'s gain at the instantaneous frequency (`shaped`; 1 without a shape).
    """
    if min(f_start, f_end) <= 0 or duration <= 0:
        raise ValueError("sweep needs positive frequencies and duration")
    t, s, dwell = _sweep_times(dt, f_start, duration, dwell_cycles)
    if law == "linear":
        cycles = f_start * s + (f_end - f_start) * s**2 / (2 * duration)
    elif law == "log":
        ratio = f_end / f_start
        if np.isclose(ratio, 1.0):
            cycles = f_start * s
        else:
            cycles = f_start * duration / np.log(ratio) * (ratio ** (s / duration) - 1)
    else:
        raise ValueError(f'sweep law must be "linear" or "log", got {law!r}')
    cycles = np.where(t < dwell, f_start * (t - dwell), cycles)
    gain = shaped(shape, sweep_frequency(s, f_start, f_end, duration, law))
    return amplitude * gain * np.sin(2 * np.pi * cycles) * raised_cosine(t.size, dt, fade)


def sweep_instants(
    dt: float,
    f_start: float,
    f_end: float,
    duration: float,
    law: str = "linear",
    dwell_cycles: float = 0.0,
) -> np.ndarray:
    """The instantaneous frequency (Hz) at each sample of `sweep` with these parameters."""
    _, s, _ = _sweep_times(dt, f_start, duration, dwell_cycles)
    return sweep_frequency(s, f_start, f_end, duration, law)


def _sweep_times(
    dt: float, f_start: float, duration: float, dwell_cycles: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """A sweep's sample times, the time into the sweep proper at each (0 while it dwells at
    f_start), and the dwell's length (s)."""
    dwell = dwell_cycles / f_start
    t = np.arange(_samples(dwell + duration, dt)) * dt
    return t, np.clip(t - dwell, 0.0, None), dwell


def split_by_frequency(u: np.ndarray, hz: np.ndarray, centres: Sequence[float]) -> list[np.ndarray]:
    """A signal whose frequency at each sample is `hz` (a sweep) split into bands about
    `centres` (Hz, ascending): one array per band, u's length, summing to u. Between two
    centres the signal passes from one band to the next along cos² and sin² in
    log-frequency (below the first centre or above the last it is all that band's): a band
    faded in and out over many cycles carries next to nothing outside its frequencies, where
    a burst cut from the sweep would carry its cut's transient to every frequency."""
    u = np.asarray(u, dtype=float)
    hz = np.asarray(hz, dtype=float)
    at = np.log(np.asarray(centres, dtype=float))
    x = np.interp(np.log(hz), at, np.arange(at.size))  # fractional band index
    out = []
    for b in range(at.size):
        weight = np.cos(np.pi / 2 * np.clip(np.abs(x - b), 0.0, 1.0)) ** 2
        out.append(u * weight)
    return out


def raised_cosine(count: int, dt: float, fade: float) -> np.ndarray:
    """Window of `count` samples rising over `fade` s as ½(1 − cos πt/fade), falling likewise."""
    w = np.ones(count)
    n = min(_samples(fade, dt), count // 2)
    if n > 0:
        ramp = 0.5 * (1 - np.cos(np.pi * np.arange(n) / n))
        w[:n] = ramp
        w[count - n :] = ramp[::-1]
    return w


def steps(dt: float, hold: float, amplitude: float, levels: Sequence[float]) -> np.ndarray:
    """A step-like sequence: each level (a multiple of `amplitude`) held for `hold` s.

    The thesis's throttle input (figure 4.4, flown after the multisines in figure 6.12) is
    levels (1, 1, −1): two counts of more throttle, one count of less.
    """
    n = _samples(hold, dt)
    return np.repeat(np.asarray(levels, dtype=float) * amplitude, n)
