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

Measured surface positions carry their potentiometers' white noise. Where a manoeuvre is short
against the record (a 3-2-1-1 of a few seconds in a minute) its spectrum's skirts stand no
higher than that noise, and a bin of pure noise is excited by chance: a regressor with noise
biases the fit (errors in variables; docs/identification.md). So a bin counts only where the
control stands SIGNAL_MARGIN times above its noise floor (`agent.ident.aircraft.noise`), the
band ends where the inputs do by the same test, and each measured input is its conditional
mean given its noise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.ident.aircraft import noise
from agent.ident.errors import DataError

# The analysis band: from the first bin to BAND_MARGIN × the highest frequency where an input
# has INPUT_LEVEL of its largest bin's power, at most a quarter of the sample rate.
BAND_MARGIN = 1.5
INPUT_LEVEL = 0.01
# Excited bins (`excited`): a control's bins with at least this share of its largest bin's power.
EXCITED_LEVEL = 0.01
# A bin of an input counts (the band's top, the excited bins) only where its power stands this
# many times above the input's white noise floor: a bin of pure noise has an exponentially
# distributed power, above ten times its mean once in e¹⁰ ≈ 22 000 bins.
SIGNAL_MARGIN = 10.0


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
    # (F, r) each input's white noise power per bin in its bin's record (as |U|²), or None
    # (noise-free inputs).
    noise: np.ndarray | None = None
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
    measured: Sequence[int] = (),
    known: Sequence[np.ndarray] | None = None,
    kinematics: np.ndarray | None = None,
    attitude: Sequence[int] = (),
    rows: Mapping[int, int] | None = None,
) -> Transforms:
    """Transforms of every experiment (X = Δt · DFT) at the bins in the analysis band;
    `measured`: input columns that are measured (noisy) signals, each taken as its conditional
    mean given its noise (module docstring); `known`: per experiment, a known forcing of each
    output's equation (samples × outputs); `kinematics`, `attitude` and `rows`: see Transforms."""
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
        U = np.fft.rfft(exp.u - exp.u.mean(axis=0), axis=0)
        power = np.abs(U) ** 2
        floors = np.array([noise.floor(p) for p in power.T]) * dt * dt
        for j in measured:
            U[:, j] = U[:, j] * noise.wiener_gain(power[:, j])
        U = U[keep] * dt
        Y = np.fft.rfft(exp.y, axis=0)[keep] * dt
        K = np.zeros_like(Y) if known is None else np.fft.rfft(known[index], axis=0)[keep] * dt
        if held_inputs:  # a zero-order hold: half a sample late, and its sinc
            w = np.abs(s) * dt / 2
            U = U * (np.exp(-s * dt / 2) * np.sinc(w / np.pi))[:, None]
        floors = np.broadcast_to(floors, U.shape)
        parts.append((s, Y, U, np.full(s.size, index), K, floors))
    if not parts:
        raise DataError("the records are too short for a single frequency bin in the band")
    s, Y, U, record, K, floors = (np.concatenate(p) for p in zip(*parts, strict=True))
    return Transforms(
        s=s,
        Y=Y,
        U=U,
        record=record,
        band_hz=(float(np.abs(s).min() / 2 / np.pi), float(top)),
        noise=floors,
        K=K,
        kinematics=kinematics,
        attitude=tuple(attitude),
        rows=dict(rows or {}),
    )


def excited(sp: Transforms, controls: Sequence[int]) -> Transforms:
    """The bins where one of `controls` puts at least EXCITED_LEVEL of its largest bin's
    power, and SIGNAL_MARGIN times its noise floor, in each record."""
    keep = np.zeros(sp.s.size, dtype=bool)
    controls = list(controls)
    for e in np.unique(sp.record):
        mine = sp.record == e
        power = np.abs(sp.U[mine][:, controls]) ** 2
        strong = power >= EXCITED_LEVEL * power.max(axis=0)
        if sp.noise is not None:
            strong &= power >= SIGNAL_MARGIN * sp.noise[mine][:, controls]
        keep[mine] = np.any(strong, axis=1)
    K = None if sp.K is None else sp.K[keep]
    floors = None if sp.noise is None else sp.noise[keep]
    return replace(
        sp, s=sp.s[keep], Y=sp.Y[keep], U=sp.U[keep], record=sp.record[keep], K=K, noise=floors
    )


def input_band(batch: Sequence, dt: float) -> float:
    """BAND_MARGIN × the highest frequency where an input puts at least INPUT_LEVEL of its
    largest bin's power and stands SIGNAL_MARGIN times above its noise floor (a multisine's top
    line, a doublet's main lobe, not the potentiometer's noise)."""
    tops = [0.0]
    for exp in batch:
        u = exp.u - exp.u.mean(axis=0)
        power = np.abs(np.fft.rfft(u, axis=0)) ** 2
        f = np.fft.rfftfreq(u.shape[0], dt)
        for column in power.T:
            strong = (column >= INPUT_LEVEL * column.max()) & (
                column >= SIGNAL_MARGIN * noise.floor(column)
            )
            if column.max() > 0 and strong.any():
                tops.append(float(f[np.flatnonzero(strong)[-1]]))
    return BAND_MARGIN * max(tops)
