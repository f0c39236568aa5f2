"""Preprocessing before identification: band, anti-alias decimation, optional smoothing.

Flight data are logged far faster than the dynamics need (thesis §4.4: the sample rate is
chosen as 25 × the highest frequency of interest). Read the other way, 50–100 Hz data for
modes below 1.5 Hz are heavily oversampled: the regression then spends its lags on sensor
noise above the band, and OKID's p must span many more samples for the same memory. Here the
band of interest is estimated from the inputs (the frequency under which BAND_POWER of every
input's power lies, not below a floor for the slowest modes), and the data are low-pass
filtered and decimated to RATE_FACTOR × that band.

Filtering keeps the input–output relation only if inputs and outputs get the same filter, so
both do, with a linear-phase FIR applied by "valid" convolution (no edge transients; the
record loses half a filter length at each end). Inputs that were held between samples
(commands, or our simulator's zero-order hold) lag their smooth equivalent by half a sample;
they are shifted back by averaging adjacent samples before filtering, so the decimated data
are samples of smooth signals and a first-order hold models them (measured on the A.2 record:
decimating 50 → 25 Hz without this correction biases the refined Dutch roll by 2.9 %, with it
by 0.4 %).

Savitzky–Golay smoothing (thesis §4.4.2) is optional and also applied to inputs and outputs
alike; it is off by default because the decimation filter already removes the out-of-band
noise it would.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal

from agent.ident.errors import DataError, InsufficientDataError
from agent.ident.okid import Experiment

# Fraction of each input's (mean-removed) power that lies inside the band of interest.
BAND_POWER = 0.99
# The band never ends below this (Hz): spiral and phugoid lie below any input band.
MIN_BAND_HZ = 0.5
# Analysis sample rate = RATE_FACTOR × band (the thesis's 25 × f_max rule).
RATE_FACTOR = 25.0
# FIR taps per unit of decimation factor (each side), and the pass band as a fraction of the
# new Nyquist frequency.
TAPS_PER_FACTOR = 10
CUTOFF = 0.8
# After decimation every experiment keeps at least this many samples.
MIN_SAMPLES = 20
# The largest decimation factor taken: beyond it the filter alone (2 × TAPS_PER_FACTOR taps
# per unit) would take gigabytes. agent/config.py holds the same bound for the config file.
MAX_DECIMATION = 1000


@dataclass(frozen=True, kw_only=True)
class Preprocessing:
    """What was done to the data before identification."""

    record_dt: float
    dt: float  # analysis sample time
    factor: int  # decimation factor (1 = none)
    band_hz: float  # band of interest used to choose the factor
    held_inputs: bool  # inputs shifted by half a sample (held between samples)
    smoothing_s: float | None  # Savitzky–Golay window, seconds
    dropped_samples: int  # per experiment end, by the filter's "valid" convolution


def input_band(batch: Sequence[Experiment], dt: float) -> float:
    """Frequency (Hz) below which BAND_POWER of every input's power lies (at least MIN_BAND_HZ)."""
    band = MIN_BAND_HZ
    for exp in batch:
        u = exp.u - exp.u.mean(axis=0)
        spectrum = np.abs(np.fft.rfft(u, axis=0)) ** 2
        freqs = np.fft.rfftfreq(u.shape[0], dt)
        for j in range(u.shape[1]):
            total = spectrum[1:, j].sum()
            if total <= 0:
                continue
            cumulative = np.cumsum(spectrum[1:, j]) / total
            band = max(band, float(freqs[1:][np.searchsorted(cumulative, BAND_POWER)]))
    return band


def decimation_factor(dt: float, band_hz: float, shortest: int) -> int:
    """Largest factor (at most MAX_DECIMATION) keeping the rate ≥ RATE_FACTOR × band and
    ≥ MIN_SAMPLES per experiment."""
    factor = min(MAX_DECIMATION, max(1, int(np.floor(1.0 / (dt * RATE_FACTOR * band_hz)))))
    while factor > 1 and (shortest - 2 * TAPS_PER_FACTOR * factor) // factor < MIN_SAMPLES:
        factor -= 1
    return factor


def lowpass_taps(factor: int) -> np.ndarray:
    """Linear-phase FIR (Hamming window) passing CUTOFF of the decimated Nyquist frequency."""
    return scipy.signal.firwin(2 * TAPS_PER_FACTOR * factor + 1, CUTOFF / factor)


def _filter(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    return scipy.signal.oaconvolve(x, taps[:, None], mode="valid", axes=0)


def preprocess(
    batch: Sequence[Experiment],
    dt: float,
    *,
    decimation: int | None = None,
    band_hz: float | None = None,
    held_inputs: bool = True,
    smoothing_s: float | None = None,
    smoothing_order: int = 3,
) -> tuple[list[Experiment], Preprocessing]:
    """The batch at the analysis rate, and what was done. `decimation` None = automatic;
    a factor is checked against MAX_DECIMATION and the records' length before its filter is
    built."""
    if decimation is not None and not 1 <= decimation <= MAX_DECIMATION:
        raise DataError(
            f"decimation {decimation} is outside 1…{MAX_DECIMATION}; give a factor in it, or "
            "leave it automatic"
        )
    band = band_hz if band_hz is not None else input_band(batch, dt)
    shortest = min(e.length for e in batch)
    factor = decimation if decimation is not None else decimation_factor(dt, band, shortest)
    out = [Experiment(e.u.astype(float), e.y.astype(float)) for e in batch]
    if smoothing_s is not None:
        window = round(smoothing_s / dt) | 1  # odd
        if window <= smoothing_order or window > shortest:
            raise InsufficientDataError(
                f"a Savitzky–Golay window of {smoothing_s} s is {window} samples: it must be "
                f"longer than the polynomial order {smoothing_order} and fit in every record "
                f"({shortest} samples)"
            )
        out = [
            Experiment(
                scipy.signal.savgol_filter(e.u, window, smoothing_order, axis=0),
                scipy.signal.savgol_filter(e.y, window, smoothing_order, axis=0),
            )
            for e in out
        ]
    dropped = 0
    if factor > 1:
        size = 2 * TAPS_PER_FACTOR * factor + 1  # lowpass_taps's, counted before it is built
        if shortest - size + 1 < MIN_SAMPLES * factor:
            raise InsufficientDataError(
                f"decimating by {factor} needs at least {MIN_SAMPLES * factor + size - 1} "
                f"samples per record; the shortest has {shortest}"
            )
        taps = lowpass_taps(factor)
        dropped = (taps.size - 1) // 2
        decimated = []
        for e in out:
            u = e.u.copy()
            if held_inputs:
                u[1:] = 0.5 * (e.u[1:] + e.u[:-1])
            decimated.append(
                Experiment(_filter(u, taps)[::factor].copy(), _filter(e.y, taps)[::factor].copy())
            )
        out = decimated
    info = Preprocessing(
        record_dt=dt,
        dt=dt * factor,
        factor=factor,
        band_hz=band,
        held_inputs=held_inputs and factor > 1,
        smoothing_s=smoothing_s,
        dropped_samples=dropped,
    )
    return out, info
