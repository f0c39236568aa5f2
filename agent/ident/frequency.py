"""Frequency-domain OKID (thesis §4.3, §4.3.1): averaged spectra → FRF → Markov parameters.

The records are cut into whole periods of the (periodic) excitation, and the auto and cross
spectral densities are averaged over every segment of every experiment (eq. 4.21–4.22), so
a batch adds its segments together. The frequency response is H = S_yu S_uu⁻¹ (eq. 4.23) at
every bin where the averaged input spectrum is well conditioned. Then:

- when every bin from 0 to Nyquist is excited by every input (broadband inputs), the system
  Markov parameters are the inverse FFT of H (eq. 4.25–4.26), Y_0 = D, Y_k = C A^{k−1} B;
- otherwise — the thesis's own multisines put each surface on a few harmonics only, so at a
  given bin only one input is known — the observer Markov parameters are fitted to the known
  FRF columns by linear least squares. With z⁻ⁱ = e^{−jωiΔt}, eq. 4.11 in the frequency
  domain reads H(ω) = D + Σ Ȳ_i⁽¹⁾ z⁻ⁱ − Σ Ȳ_i⁽²⁾ z⁻ⁱ H(ω), linear in the Ȳ_i (Levy's
  matrix-fraction fit), and the system Markov parameters follow by eq. 4.14 as in the time
  domain. This fits the excited bins only, so the noise between them never enters.

Both feed ERA. Leakage (appendix A.1): an input that is not periodic over the segment puts
power between the harmonics; the relative difference of the input between the segment and
the period before it, e = ‖u(τ + l) − u(τ)‖/‖u‖, is reported and warned about above
LEAKAGE_WARN. A record with no periodic input is cut into half-overlapping Hann-windowed
segments instead (Welch), with a warning that leakage is then only reduced, not removed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.ident.errors import DataError, InsufficientDataError
from agent.ident.okid import MIN_ROWS_PER_UNKNOWN, Experiment, ObserverMarkov

# An input repeats with period L when ‖u(k + L) − u(k)‖ ≤ PERIOD_TOLERANCE · ‖u‖.
PERIOD_TOLERANCE = 0.01
# Warn about leakage above this relative non-periodicity of the input (appendix A.1).
LEAKAGE_WARN = 0.01
# A bin's input spectral matrix counts as excited for an input when that input's power there
# exceeds this fraction of its largest bin power.
EXCITED_FRACTION = 1e-3
# A given excitation period shorter than this many samples cannot hold a multisine.
MIN_PERIOD = 8
# Welch segments (no periodic input): this many samples at least, and 50 % overlap.
MIN_WELCH_SEGMENT = 64


@dataclass(frozen=True, kw_only=True)
class Spectra:
    """Averaged spectral densities over all segments (eq. 4.22)."""

    freqs: np.ndarray  # (F,) Hz
    Suu: np.ndarray  # (F, r, r)
    Syu: np.ndarray  # (F, m, r)
    Syy: np.ndarray  # (F, m) the outputs' auto-spectra (coherence)
    segments: int
    segment_length: int
    periodic: bool  # whole periods (True) or Hann-windowed Welch segments
    leakage: float  # relative input non-periodicity over the segments (0 if periodic)


@dataclass(frozen=True)
class FrequencyResponse:
    """H(ω) per bin; `known[f, j]` says whether input j's column is determined at bin f."""

    freqs: np.ndarray
    H: np.ndarray  # (F, m, r), nan where unknown
    known: np.ndarray  # (F, r) bool

    @property
    def broadband(self) -> bool:
        """Every input known at every bin strictly between DC and Nyquist."""
        return bool(np.all(self.known[1:-1]))


# The period test compares the record with itself shifted by the lag over at least this
# fraction of the record (a 30 s record of a 20 s period overlaps itself over 10 s).
MIN_OVERLAP = 0.25


def detect_period(u: np.ndarray, shortest: int = 8) -> int | None:
    """Smallest lag L with ‖u(k+L) − u(k)‖ ≤ PERIOD_TOLERANCE ‖u‖ over the overlap."""
    u = u - u.mean(axis=0)
    length = u.shape[0]
    energy = float(np.sum(u**2))
    if energy == 0:
        return None
    for lag in range(shortest, int(length * (1 - MIN_OVERLAP)) + 1):
        diff = u[lag:] - u[:-lag]
        if np.sum(diff**2) <= PERIOD_TOLERANCE**2 * energy * (length - lag) / length:
            return lag
    return None


def _segments(exp: Experiment, length: int, periodic: bool) -> list[tuple[int, int]]:
    """(start, stop) of the segments used: the last whole periods, or 50 % overlapped.

    With two or more whole periods the first is left out: it holds the start-up transient.
    """
    if periodic:
        count = exp.length // length
        first = exp.length - count * length
        skip = 1 if count >= 2 else 0
        return [(first + k * length, first + (k + 1) * length) for k in range(skip, count)]
    step = length // 2
    return [(s, s + length) for s in range(0, exp.length - length + 1, step)]


def averaged_spectra(batch: Sequence[Experiment], period: int | None) -> Spectra:
    """Spectral densities averaged over whole periods (or Welch segments) of every experiment."""
    shortest = min(e.length for e in batch)
    periodic = period is not None and period <= shortest
    if periodic:
        length = int(period)
        window = np.ones(length)
    else:
        length = max(MIN_WELCH_SEGMENT, shortest // 4)
        if length > shortest:
            raise InsufficientDataError(
                f"frequency-domain OKID needs records of at least {MIN_WELCH_SEGMENT} samples"
            )
        window = np.hanning(length)
    r, m = batch[0].u.shape[1], batch[0].y.shape[1]
    F = length // 2 + 1
    Suu = np.zeros((F, r, r), dtype=complex)
    Syu = np.zeros((F, m, r), dtype=complex)
    Syy = np.zeros((F, m))
    count, leak_num, leak_den = 0, 0.0, 0.0
    for exp in batch:
        for start, stop in _segments(exp, length, periodic):
            U = np.fft.rfft(exp.u[start:stop] * window[:, None], axis=0)
            Y = np.fft.rfft(exp.y[start:stop] * window[:, None], axis=0)
            Suu += np.einsum("fi,fj->fij", U, U.conj())
            Syu += np.einsum("fi,fj->fij", Y, U.conj())
            Syy += np.abs(Y) ** 2
            count += 1
            if periodic and start >= length:
                # Appendix A.1: the input over the segment against the period before it.
                leak_num += float(np.sum((exp.u[start:stop] - exp.u[start - length : start]) ** 2))
                leak_den += float(np.sum(exp.u[start:stop] ** 2))
    leakage = float(np.sqrt(leak_num / leak_den)) if leak_den > 0 else 0.0
    return Spectra(
        freqs=np.fft.rfftfreq(length),
        Suu=Suu / count,
        Syu=Syu / count,
        Syy=Syy / count,
        segments=count,
        segment_length=length,
        periodic=periodic,
        leakage=leakage,
    )


def frequency_response(spectra: Spectra) -> FrequencyResponse:
    """H = S_yu S_uu⁻¹ where every input is excited; single columns where only one input is."""
    F, m, r = spectra.Syu.shape
    power = np.real(np.einsum("fii->fi", spectra.Suu))  # (F, r)
    peak = power.max(axis=0)
    excited = power > EXCITED_FRACTION * np.where(peak > 0, peak, np.inf)
    H = np.full((F, m, r), np.nan, dtype=complex)
    known = np.zeros((F, r), dtype=bool)
    for f in range(F):
        inputs = np.flatnonzero(excited[f])
        if inputs.size == 0:
            continue
        sub = spectra.Suu[f][np.ix_(inputs, inputs)]
        if np.linalg.cond(sub) > 1e8:
            continue
        # Inputs silent at this bin carry (next to) no power here, so S_yu holds nothing of
        # theirs and the excited columns are determined on their own.
        H[f][:, inputs] = spectra.Syu[f][:, inputs] @ np.linalg.inv(sub)
        known[f, inputs] = True
    return FrequencyResponse(spectra.freqs, H, known)


def inverse_fft_markov(frf: FrequencyResponse, count: int) -> np.ndarray:
    """System Markov parameters Y_0 … Y_(count−1) by the inverse FFT of H (eq. 4.26)."""
    length = 2 * (frf.freqs.size - 1)
    H = frf.H.copy()
    # DC and Nyquist are rarely excited (zero-mean, band-limited inputs). H is real there and
    # its real part is even about both, Re H(ω₀ ± δ) = a + b δ² + …, so a = (4 Re H₁ − Re H₂)/3
    # from the two nearest bins.
    for edge, near, next_ in ((0, 1, 2), (-1, -2, -3)):
        missing = ~frf.known[edge]
        H[edge][:, missing] = (4 * H[near][:, missing].real - H[next_][:, missing].real) / 3
    H[0], H[-1] = H[0].real, H[-1].real
    Y = np.fft.irfft(H, n=length, axis=0)  # (length, m, r)
    if count > length:
        raise InsufficientDataError(
            f"{count} Markov parameters asked from a {length}-sample segment"
        )
    return Y[:count]


def max_markov(frf: FrequencyResponse, estimate_d: bool) -> int:
    """Largest p the known FRF columns determine (MIN_ROWS_PER_UNKNOWN equations each)."""
    m, r = frf.H.shape[1], frf.H.shape[2]
    equations = 2 * int(frf.known.sum())  # real equations per output row
    p = 0
    while (p + 1) * (r + m) + (r if estimate_d else 0) <= equations / MIN_ROWS_PER_UNKNOWN:
        p += 1
    return p


def observer_markov_from_frf(
    frf: FrequencyResponse, p: int, estimate_d: bool = False
) -> ObserverMarkov:
    """Ȳ_i⁽¹⁾, Ȳ_i⁽²⁾ (and D) fitted to the known FRF columns (module text).

    Frequencies in `frf.freqs` are in cycles per sample, so z⁻ⁱ = exp(−j 2π f i).
    """
    F, m, r = frf.H.shape
    if p < 1 or p > max_markov(frf, estimate_d):
        raise InsufficientDataError(
            f"the excited frequencies determine at most p = {max_markov(frf, estimate_d)} "
            f"observer Markov parameters, not {p}; excite more harmonics or use the time domain"
        )
    rows, targets = [], []
    lags = np.arange(1, p + 1)
    for f in range(F):
        zinv = np.exp(-2j * np.pi * frf.freqs[f] * lags)  # (p,)
        for j in np.flatnonzero(frf.known[f]):
            h = frf.H[f][:, j]  # (m,)
            e = np.zeros(r)
            e[j] = 1.0
            parts = []
            if estimate_d:
                parts.append(e.astype(complex))
            parts.append(np.outer(zinv, e).ravel())  # Ȳ1_i[a, :] coefficients
            parts.append(-np.outer(zinv, h).ravel())  # Ȳ2_i[a, :] coefficients
            rows.append(np.concatenate(parts))
            targets.append(h)
    Phi = np.array(rows)  # (K, unknowns), complex
    T = np.array(targets)  # (K, m), complex
    real_phi = np.vstack([Phi.real, Phi.imag])
    real_t = np.vstack([T.real, T.imag])
    theta, *_ = np.linalg.lstsq(real_phi, real_t, rcond=None)  # (unknowns, m)
    offset = r if estimate_d else 0
    D = theta[:r].T if estimate_d else np.zeros((m, r))
    Ybar1 = theta[offset : offset + p * r].T.reshape(m, p, r).transpose(1, 0, 2)
    Ybar2 = theta[offset + p * r :].T.reshape(m, p, m).transpose(1, 0, 2)
    residual = real_t - real_phi @ theta
    return ObserverMarkov(
        D=D,
        Ybar1=Ybar1,
        Ybar2=Ybar2,
        rows=int(real_phi.shape[0]),
        residual_rms=np.sqrt(np.mean(residual**2, axis=0)),
        singular_values=np.linalg.svd(real_phi, compute_uv=False),
        rank=int(np.linalg.matrix_rank(real_phi)),
    )


def markov_observer(markov: np.ndarray) -> ObserverMarkov:
    """System Markov parameters dressed as observer ones with no observer (Ȳ⁽²⁾ = 0)."""
    count, m, _ = markov.shape
    return ObserverMarkov(
        D=markov[0].copy(),
        Ybar1=markov[1:].copy(),
        Ybar2=np.zeros((count - 1, m, m)),
        rows=0,
        residual_rms=np.zeros(m),
        singular_values=np.zeros(0),
        rank=0,
    )


@dataclass(frozen=True, kw_only=True)
class FrequencyData:
    """Spectra and FRF of a batch, and the warnings they raise."""

    spectra: Spectra
    frf: FrequencyResponse
    period: int | None
    warnings: tuple[str, ...]


def analyse(batch: Sequence[Experiment], period: int | None = None) -> FrequencyData:
    """Spectra and FRF of the batch; the period is detected from the first record if not given."""
    warnings = []
    shortest = min(e.length for e in batch)
    if period is not None and not MIN_PERIOD <= period <= shortest:
        raise DataError(
            f"an excitation period of {period} samples is unusable: it must be at least "
            f"{MIN_PERIOD} samples and fit in every record ({shortest} samples)"
        )
    if period is None:
        period = detect_period(batch[0].u)
    if period is None:
        warnings.append(
            "the inputs are not periodic: the frequency response uses Hann-windowed segments, "
            "which reduces leakage but does not remove it (thesis appendix A.1)"
        )
    spectra = averaged_spectra(batch, period)
    if spectra.periodic and spectra.leakage > LEAKAGE_WARN:
        warnings.append(
            f"the input differs by {100 * spectra.leakage:.1f} % between consecutive periods: "
            "spectral leakage (thesis appendix A.1)"
        )
    if spectra.periodic and any(e.length < 2 * spectra.segment_length for e in batch):
        warnings.append(
            "a record holds only one whole period of the excitation: the start-up transient "
            "is in the window and leaks between the harmonics; fly at least two periods"
        )
    return FrequencyData(
        spectra=spectra,
        frf=frequency_response(spectra),
        period=period,
        warnings=tuple(warnings),
    )
