"""A measured signal's white noise floor, and its conditional mean given that noise.

The floor is the periodogram's mean above FLOOR_FROM of the Nyquist frequency, where no flight
manoeuvre and no gust puts power: what is left there is the sensor's white noise, and white
noise has that level at every frequency. The conditional mean scales each frequency bin by the
Wiener gain max(0, 1 − N/P), P the periodogram smoothed over SMOOTH_BINS bins a side and N the
floor: where the signal stands far above its noise it is kept, where it does not it goes.

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
# `detected`: the chance that white noise alone passes, over a whole record.
FALSE_ALARM = 1e-3


def floor(power: np.ndarray) -> float:
    """The white noise floor of a periodogram (its bins from DC up; FLOOR_FROM)."""
    return float(np.mean(power[int(FLOOR_FROM * power.size) :]))


def smoothed(power: np.ndarray) -> np.ndarray:
    """A periodogram averaged over SMOOTH_BINS bins on either side."""
    return scipy.ndimage.uniform_filter1d(power, 2 * SMOOTH_BINS + 1, mode="nearest")


def wiener_gain(power: np.ndarray) -> np.ndarray:
    """Per bin of a periodogram, the gain that takes the signal to its conditional mean."""
    return np.clip(1.0 - floor(power) / np.maximum(smoothed(power), 1e-300), 0.0, 1.0)


def conditional_mean(g: np.ndarray) -> np.ndarray:
    """A sampled signal's conditional mean given its white measurement noise (its mean kept)."""
    mean = float(g.mean())
    G = np.fft.rfft(g - mean)
    return np.fft.irfft(wiener_gain(np.abs(G) ** 2) * G, n=g.size) + mean


def detected(g: np.ndarray) -> bool:
    """Whether a sampled signal holds more than its white measurement noise: its periodogram,
    smoothed over SMOOTH_BINS bins a side, stands above the floor somewhere below FLOOR_FROM
    by more than white noise reaches with probability FALSE_ALARM over the record. White
    noise's smoothed periodogram over its floor is a Gamma variable of shape 2·SMOOTH_BINS + 1
    and mean 1 at each bin; the blocks of that width are counted as independent trials."""
    power = np.abs(np.fft.rfft(g - g.mean())) ** 2
    level = floor(power)
    width = 2 * SMOOTH_BINS + 1
    below = smoothed(power)[1 : int(FLOOR_FROM * power.size)]
    if level <= 0 or below.size == 0:
        return bool(np.any(below > 0))
    trials = max(1, below.size // width)
    threshold = scipy.stats.gamma.isf(FALSE_ALARM / trials, a=width, scale=1.0 / width)
    return bool(np.any(below > threshold * level))
