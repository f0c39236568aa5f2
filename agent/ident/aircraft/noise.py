"""A measured signal's white noise floor, and its conditional mean given that noise.

The floor is the periodogram's mean above FLOOR_FROM of the Nyquist frequency, where no flight
manoeuvre and no gust puts power: what is left there is the sensor's white noise, and white
noise has that level at every frequency. The conditional mean scales each frequency bin by the
Wiener gain max(0, 1 − N/P), P the periodogram smoothed over SMOOTH_BINS bins a side and N the
floor: where the signal stands far above its noise it is kept, where it does not it goes.
A bin whose smoothed power pure noise could reach (below DETECTED times the floor) goes
whole: the Wiener gain of a pure-noise bin is random, about a quarter where chance lifts the
smoothed power above the floor, and the noise it leaves is no longer white against the fit.

Why the conditional mean: a regressor with noise biases its own gain toward zero and the rest
of the fit with it (errors in variables); its conditional mean is a regressor whose error is
uncorrelated with it, so linear gains fitted on it are consistent (regression calibration;
Carroll, Ruppert, Stefanski & Crainiceanu, *Measurement Error in Nonlinear Models*, 2nd ed.,
2006, ch. 4)."""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.stats

FLOOR_FROM = 0.5
SMOOTH_BINS = 8
# The smoothed power of pure white noise over 2·SMOOTH_BINS + 1 bins, in units of its floor, is
# Gamma-distributed with that many degrees of freedom; DETECTED is the level it passes once in
# e¹⁰ ≈ 22 000 bins (agent.ident.aircraft.transforms.SIGNAL_MARGIN's rate for single bins).
_SMOOTHED = 2 * SMOOTH_BINS + 1
DETECTED = float(scipy.stats.gamma.isf(np.exp(-10.0), _SMOOTHED, scale=1.0 / _SMOOTHED))


def floor(power: np.ndarray) -> float:
    """The white noise floor of a periodogram (its bins from DC up; FLOOR_FROM)."""
    return float(np.mean(power[int(FLOOR_FROM * power.size) :]))


def wiener_gain(power: np.ndarray, detected: float = 0.0) -> np.ndarray:
    """Per bin of a periodogram, the gain that takes the signal to its conditional mean; 0
    where the smoothed power stands below `detected` times the noise floor."""
    smooth = scipy.ndimage.uniform_filter1d(power, _SMOOTHED, mode="nearest")
    level = floor(power)
    gain = np.clip(1.0 - level / np.maximum(smooth, 1e-300), 0.0, 1.0)
    return np.where(smooth >= detected * level, gain, 0.0)


def conditional_mean(g: np.ndarray) -> np.ndarray:
    """A sampled signal's conditional mean given its white measurement noise (its mean kept),
    only the bins where it stands DETECTED above that noise."""
    mean = float(g.mean())
    G = np.fft.rfft(g - mean)
    return np.fft.irfft(wiener_gain(np.abs(G) ** 2, DETECTED) * G, n=g.size) + mean
