"""A record's measured frequency response and coherence, and an identified model's beside it:
the Bode plot with coherence by which a flight-test engineer judges a model (CIFER, SIDPAC).

The spectra are `frequency.averaged_spectra`'s: averaged over whole periods when the
excitation repeats at least MIN_PERIODS times in every record (the first period, with the
start-up transient, left out, so the others are the averages), else over half-overlapping
Hann-windowed segments of a quarter of the shortest record (Welch). At each bin the inputs
with power there (EXCITED_FRACTION of their strongest bin) give their columns of
H = S_yu S_uu⁻¹ (thesis eq. 4.23; one input alone: the H1 estimate S_yu / S_uu), so the
simultaneous inputs of a multi-axis manoeuvre are separated where their spectra overlap, and
an input is shown only where it put power.

Coherence is the multiple coherence of each output with the inputs excited at the bin,
γ² = S_yu S_uu⁻¹ S_uy / S_yy (Bendat & Piersol, *Random Data*, 4th ed., 2010, §7.3; one input
alone: the ordinary coherence |S_yu|² / (S_uu S_yy)): the fraction of the output's power the
inputs explain linearly. Noise, turbulence, nonlinearity and inputs not in the model lower it.
It needs two segments at least (one segment gives γ² = 1 whatever the data); a record too
short for two has none. Where γ² < COHERENCE_MIN (CIFER's guideline, Tischler & Remple,
*Aircraft and Rotorcraft System Identification*, 2nd ed., 2012, ch. 7) the measured response
is not to be trusted, and a model that misses it there is not wrong for that.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.ident.frequency import averaged_spectra, detect_period
from agent.ident.okid import Experiment

# Whole periods a record must hold for period averaging (the first is left out: two remain).
MIN_PERIODS = 3
# An input counts as excited at a bin when its power there is this fraction of its peak.
EXCITED_FRACTION = 1e-2
# Below this coherence the measured response is not to be trusted.
COHERENCE_MIN = 0.6


@dataclass(frozen=True, kw_only=True)
class MeasuredResponse:
    """H and γ² at the bins where some input is excited; nan where an input is not."""

    freqs: np.ndarray  # (F,) Hz
    H: np.ndarray  # (F, m, r) complex
    coherence: np.ndarray  # (F, m, r), nan without two segments
    averaging: str  # "periods" or "welch"
    segments: int
    segment_s: float

    def excited(self, i: int) -> np.ndarray:
        """The bins where input i is excited (bool, (F,))."""
        return np.isfinite(self.H[:, 0, i])

    def low_coherence(self, i: int, j: int) -> float | None:
        """The fraction of input i's excited bins where output j's coherence is below
        COHERENCE_MIN (None: no coherence, or input i not excited)."""
        g = self.coherence[self.excited(i), j, i]
        if g.size == 0 or not np.isfinite(g).all():
            return None
        return float(np.mean(g < COHERENCE_MIN))


def measured(batch: Sequence[Experiment], dt: float, period: int | None = None) -> MeasuredResponse:
    """The measured frequency response of a batch sampled every `dt` s. `period`: the
    excitation's period in samples (None: detected from the first record's inputs)."""
    shortest = min(e.length for e in batch)
    if period is None:
        period = detect_period(batch[0].u)
    if period is not None and shortest < MIN_PERIODS * period:
        period = None  # too few periods to average: Welch segments instead
    spectra = averaged_spectra(batch, period)
    power = np.real(np.einsum("fii->fi", spectra.Suu))  # (F, r)
    peak = power.max(axis=0)
    excited = power > EXCITED_FRACTION * np.where(peak > 0, peak, np.inf)
    F, m, r = spectra.Syu.shape
    H = np.full((F, m, r), np.nan, dtype=complex)
    coherence = np.full((F, m, r), np.nan)
    for f in np.flatnonzero(excited.any(axis=1)):
        inputs = np.flatnonzero(excited[f])
        Suu = spectra.Suu[f][np.ix_(inputs, inputs)]
        if np.linalg.cond(Suu) > 1e8:  # the inputs move together here: not separable
            continue
        Syu = spectra.Syu[f][:, inputs]
        H[f][:, inputs] = Syu @ np.linalg.inv(Suu)
        if spectra.segments >= 2:
            explained = np.real(np.einsum("ji,ji->j", H[f][:, inputs], Syu.conj()))
            gamma = explained / np.where(spectra.Syy[f] > 0, spectra.Syy[f], np.inf)
            coherence[f][:, inputs] = np.clip(gamma, 0.0, 1.0)[:, None]
    keep = np.isfinite(H[:, 0, :]).any(axis=1)
    keep[0] = False  # DC: the trim, not the dynamics
    return MeasuredResponse(
        freqs=spectra.freqs[keep] / dt,
        H=H[keep],
        coherence=coherence[keep],
        averaging="periods" if spectra.periodic else "welch",
        segments=spectra.segments,
        segment_s=spectra.segment_length * dt,
    )


def model_response(A, B, C, D, dt: float, freqs: np.ndarray) -> np.ndarray:
    """A discrete model's frequency response at `freqs` (Hz), (F, m, r)."""
    A, B, C, D = (np.asarray(x, dtype=float) for x in (A, B, C, D))
    eye = np.eye(A.shape[0])
    z = np.exp(2j * np.pi * np.asarray(freqs) * dt)
    return np.array([C @ np.linalg.solve(zk * eye - A, B) + D for zk in z])
