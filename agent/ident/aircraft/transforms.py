"""The records in the frequency domain: finite Fourier transforms at the analysis bins, and the
bins each axis is fitted on.

With X(ω) the finite Fourier transform of a record of length T at ω_k = 2πk/T (k ≠ 0), a
linear model ẋ = A x + B u reads exactly X(ω_k) = (jω_k I − A)⁻¹ (B U(ω_k) − d), where
d = x(T) − x(0) is the record's transient term (Pintelon & Schoukens, *System Identification:
A Frequency Domain Approach*, 2012, §6.3). It carries whatever initial and final state the
record has, so no periodicity and no steady state are needed, and a constant offset (a trim
error) lives only at DC, which is not fitted. Only the bins up to the band's top are used, so
the cost does not grow with the record's length.

Each axis is fitted on its excited bins only (`excited`): those where one of its own controls
puts at least EXCITED_LEVEL of its largest bin's power, as Morelli's SIDPAC `fdoe` fits the
excited frequencies. The rest of the band carries no information about the axis and is where
the nonlinear distortion goes: a lateral manoeuvre reaches the longitudinal axis through even
functions of β, p, r (sideslip drag ∝ β²), which odd-harmonic inputs put on even harmonics,
away from the elevator's lines.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.ident.errors import DataError

# The analysis band: from the first bin to BAND_MARGIN × the highest frequency where an input
# has INPUT_LEVEL of its largest bin's power, at most a quarter of the sample rate.
BAND_MARGIN = 1.5
INPUT_LEVEL = 0.01
# Excited bins (`excited`): a control's bins with at least this share of its largest bin's power.
EXCITED_LEVEL = 0.01


# Not agent.ident.frequency.Spectra (densities averaged over segments): transforms of whole
# records at the analysis bins.
@dataclass(frozen=True, kw_only=True)
class Transforms:
    """Finite Fourier transforms of the batch at the analysis bins (bins of all records)."""

    s: np.ndarray  # (F,) jω
    Y: np.ndarray  # (F, m)
    U: np.ndarray  # (F, r)
    record: np.ndarray  # (F,) which experiment each bin comes from
    band_hz: tuple[float, float]
    K: np.ndarray | None = None  # (F, m) known forcing of each output's equation (kinematics)
    # The kinematics' linear part at the trim in output columns (m × m; zero where only forces
    # act), and the output columns of θ and φ, whose rows and columns it fixes (AxisProblem).
    kinematics: np.ndarray | None = None
    attitude: tuple[int, ...] = ()
    # Known inputs that enter one equation only: input column → output column (sideslip drag
    # acts on V̇ alone).
    rows: Mapping[int, int] = field(default_factory=dict)


def transforms(
    batch: Sequence,
    dt: float,
    band_hz: float | None,
    *,
    held_inputs: bool,
    known: Sequence[np.ndarray] | None = None,
    kinematics: np.ndarray | None = None,
    attitude: Sequence[int] = (),
    rows: Mapping[int, int] | None = None,
) -> Transforms:
    """Transforms of every experiment (X = Δt · DFT) at the bins in the analysis band;
    `known`: per experiment, a known forcing of each output's equation (samples × outputs);
    `kinematics`, `attitude` and `rows`: see Transforms."""
    top = band_hz or input_band(batch, dt)
    top = min(top, 0.25 / dt)
    parts = []
    for index, exp in enumerate(batch):
        n = exp.u.shape[0]
        f = np.fft.rfftfreq(n, dt)
        keep = (f > 0) & (f <= top)
        if keep.sum() == 0:
            continue
        s = 2j * np.pi * f[keep]
        U = np.fft.rfft(exp.u, axis=0)[keep] * dt
        Y = np.fft.rfft(exp.y, axis=0)[keep] * dt
        K = np.zeros_like(Y) if known is None else np.fft.rfft(known[index], axis=0)[keep] * dt
        if held_inputs:  # a zero-order hold: half a sample late, and its sinc
            w = np.abs(s) * dt / 2
            U = U * (np.exp(-s * dt / 2) * np.sinc(w / np.pi))[:, None]
        parts.append((s, Y, U, np.full(s.size, index), K))
    if not parts:
        raise DataError("the records are too short for a single frequency bin in the band")
    s, Y, U, record, K = (np.concatenate(p) for p in zip(*parts, strict=True))
    return Transforms(
        s=s,
        Y=Y,
        U=U,
        record=record,
        band_hz=(float(np.abs(s).min() / 2 / np.pi), float(top)),
        K=K,
        kinematics=kinematics,
        attitude=tuple(attitude),
        rows=dict(rows or {}),
    )


def excited(sp: Transforms, controls: Sequence[int]) -> Transforms:
    """The bins where one of `controls` puts at least EXCITED_LEVEL of its largest bin's
    power, in each record."""
    keep = np.zeros(sp.s.size, dtype=bool)
    for e in np.unique(sp.record):
        mine = sp.record == e
        power = np.abs(sp.U[mine][:, list(controls)]) ** 2
        keep[mine] = np.any(power >= EXCITED_LEVEL * power.max(axis=0), axis=1)
    K = None if sp.K is None else sp.K[keep]
    return replace(sp, s=sp.s[keep], Y=sp.Y[keep], U=sp.U[keep], record=sp.record[keep], K=K)


def input_band(batch: Sequence, dt: float) -> float:
    """BAND_MARGIN × the highest frequency where an input puts at least INPUT_LEVEL of its
    largest bin's power (a multisine's top line, a doublet's main lobe; measured positions'
    noise floor lies far below)."""
    tops = [0.0]
    for exp in batch:
        u = exp.u - exp.u.mean(axis=0)
        power = np.abs(np.fft.rfft(u, axis=0)) ** 2
        f = np.fft.rfftfreq(u.shape[0], dt)
        for column in power.T:
            if column.max() > 0:
                tops.append(float(f[np.flatnonzero(column >= INPUT_LEVEL * column.max())[-1]]))
    return BAND_MARGIN * max(tops)
