"""What to play: a Plan of segments of signals on controls, the thesis's presets, rendering at
the command rate, and the checks a plan must pass before it may start.

A Plan is a small frozen pydantic model: its compact JSON (`Plan.to_bytes`) is what the ground
sends over the radio, and the onboard agent renders exactly what the ground previewed (every
signal, phase optimisation included, is deterministic). Amplitudes are in each control's unit
(surface degrees, throttle percent) from trim.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from agent.channels import AXIS_SETS
from agent.config import Envelope, Surface
from agent.excitation import servo, signals
from agent.excitation.names import CONTROLS, PRESETS

AxisSet = Literal["lateral", "longitudinal", "full"]
Nonzero = Annotated[float, Field(allow_inf_nan=False)]
# A multisine harmonic's bound. The highest one that can play is 60,000 (period_s ≤ 120 s,
# a command rate ≤ 1000 Hz); above that the Nyquist refusal names the frequency. The bound
# sits far above it and only keeps an integer of hundreds of digits (10**400, which no float
# holds) out of the frequency arithmetic.
MAX_HARMONIC = 10**9
Harmonic = Annotated[int, Field(ge=1, le=MAX_HARMONIC)]
# A spectral shape's breakpoint: (frequency in Hz, gain on the amplitude in (0, 1]); a shape
# only takes amplitude away, so a signal's amplitude stays its largest.
Breakpoint = tuple[
    Annotated[float, Field(gt=0.0, le=1000.0)], Annotated[float, Field(gt=0.0, le=1.0)]
]
MAX_BREAKPOINTS = 64


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class _Signal(_Model):
    amplitude: Nonzero
    """Peak deflection from trim in the control's unit; negative reverses the signal."""

    @field_validator("amplitude")
    @classmethod
    def _nonzero(cls, value: float) -> float:
        if value == 0:
            raise ValueError("amplitude must not be 0")
        return value


class _Shaped(_Signal):
    """A signal whose amplitude may vary with frequency: `shape` is breakpoints (Hz, gain),
    ascending, interpolated in log-frequency and held beyond its ends (`signals.shaped`);
    the sizing shapes a sweep or a multisine to the response it causes (agent/sizing.py)."""

    shape: tuple[Breakpoint, ...] = Field((), max_length=MAX_BREAKPOINTS)

    @field_validator("shape")
    @classmethod
    def _ascending(cls, value: tuple[Breakpoint, ...]) -> tuple[Breakpoint, ...]:
        hz = [f for f, _ in value]
        if any(b <= a for a, b in itertools.pairwise(hz)):
            raise ValueError("a shape's breakpoints must be in strictly ascending frequency")
        return value


class _Pulses(_Signal):
    """A `pattern` of pulses (`signals.pulses`) in units of `pulse_s`, which each subclass
    declares with its own bound."""

    pattern: ClassVar[tuple[int, ...]]

    def samples(self, dt: float) -> np.ndarray:
        return signals.pulses(dt, self.pulse_s, self.amplitude, self.pattern)

    @property
    def duration_s(self) -> float:
        return sum(abs(n) for n in self.pattern) * self.pulse_s

    @property
    def shortest_s(self) -> float:
        return self.pulse_s


class Doublet(_Pulses):
    """+A then −A, each for `pulse_s` seconds."""

    pattern = signals.DOUBLET
    kind: Literal["doublet"] = "doublet"
    pulse_s: float = Field(gt=0.0, le=30.0)


class ThreeTwoOneOne(_Pulses):
    """3-2-1-1 with unit pulse `pulse_s` (7 units in all)."""

    pattern = signals.THREE_TWO_ONE_ONE
    kind: Literal["3211"] = "3211"
    pulse_s: float = Field(gt=0.0, le=10.0)


class Sweep(_Shaped):
    """Sine sweep from f0_hz to f1_hz over duration_s (linear or logarithmic law)."""

    kind: Literal["sweep"] = "sweep"
    f0_hz: float = Field(gt=0.0)
    f1_hz: float = Field(gt=0.0)
    duration_s: float = Field(gt=0.0, le=300.0)
    law: Literal["linear", "log"] = "linear"
    fade_s: float = Field(0.0, ge=0.0)
    dwell_cycles: float = Field(0.0, ge=0.0, le=20.0)

    def samples(self, dt: float) -> np.ndarray:
        return signals.sweep(
            dt,
            self.f0_hz,
            self.f1_hz,
            self.duration_s,
            self.amplitude,
            self.law,
            self.fade_s,
            self.dwell_cycles,
            self.shape,
        )

    def bands(self, dt: float, centres: Sequence[float]) -> list[np.ndarray]:
        """The sweep without its shape, split by its instantaneous frequency into bands about
        `centres` (Hz, ascending; `signals.split_by_frequency`): one array per band, the
        sweep's length, summing to the sweep."""
        flat = self.model_copy(update={"shape": ()}).samples(dt)
        hz = signals.sweep_instants(
            dt, self.f0_hz, self.f1_hz, self.duration_s, self.law, self.dwell_cycles
        )
        return signals.split_by_frequency(flat, hz, centres)

    @property
    def top_hz(self) -> float:
        return max(self.f0_hz, self.f1_hz)

    @property
    def played_s(self) -> float:
        """The dwell at f0_hz, then the sweep."""
        return self.dwell_cycles / self.f0_hz + self.duration_s


class Multisine(_Shaped):
    """Harmonics k of 1/period_s, `periods` periods long (eq. 4.30), started at a zero
    crossing so whole periods begin and end at trim; equal amplitudes (their peak is
    `amplitude`) unless `shape` lowers some."""

    kind: Literal["multisine"] = "multisine"
    harmonics: tuple[Harmonic, ...] = Field(min_length=1, max_length=64)
    period_s: float = Field(gt=0.0, le=120.0)
    periods: float = Field(2.0, gt=0.0, le=20.0)
    phases: Literal["optimised", "schroeder"] = "optimised"

    @field_validator("harmonics")
    @classmethod
    def _distinct(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        if min(value) < 1 or len(set(value)) != len(value):
            raise ValueError("harmonics must be distinct integers ≥ 1")
        return value

    def samples(self, dt: float) -> np.ndarray:
        return self._played(dt, signals.shaped(self.shape, self.hz))

    @property
    def hz(self) -> np.ndarray:
        """Each harmonic's frequency, in `harmonics` order."""
        return np.asarray(self.harmonics, dtype=float) / self.period_s

    def _played(self, dt: float, gains: np.ndarray) -> np.ndarray:
        phases = signals.zero_start(
            self.harmonics,
            signals.low_peak_phases(self.harmonics)
            if self.phases == "optimised"
            else signals.schroeder_phases(len(self.harmonics)),
            gains,
        )
        return signals.multisine(
            self.harmonics,
            self.period_s,
            dt,
            self.periods * self.period_s,
            self.amplitude,
            phases,
            gains,
        )

    @property
    def top_hz(self) -> float:
        return max(self.harmonics) / self.period_s

    @property
    def duration_s(self) -> float:
        return self.periods * self.period_s


class Steps(_Signal):
    """Step-like sequence: each level × amplitude held for hold_s (levels within ±1)."""

    kind: Literal["steps"] = "steps"
    levels: tuple[float, ...] = Field(min_length=1, max_length=32)
    hold_s: float = Field(gt=0.0, le=60.0)

    @field_validator("levels")
    @classmethod
    def _unit(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        if any(not -1.0 <= v <= 1.0 for v in value):
            raise ValueError("levels are multiples of the amplitude within −1 … 1")
        return value

    def samples(self, dt: float) -> np.ndarray:
        return signals.steps(dt, self.hold_s, self.amplitude, self.levels)

    @property
    def duration_s(self) -> float:
        return len(self.levels) * self.hold_s

    @property
    def shortest_s(self) -> float:
        return self.hold_s


Signal = Annotated[
    Doublet | ThreeTwoOneOne | Sweep | Multisine | Steps, Field(discriminator="kind")
]


class Segment(_Model):
    """Signals that start together on their controls, then free response for free_s."""

    signals: dict[str, Signal] = Field(min_length=1)
    free_s: float = Field(0.0, ge=0.0, le=120.0)


class Plan(_Model):
    """An excitation run: trim for lead_s, then the segments in order."""

    id: str = Field(min_length=1, max_length=16, pattern=r"^[A-Za-z0-9_.\-]+$")
    axes: AxisSet
    """Identification type the run is flown for (which model the job identifies)."""
    segments: tuple[Segment, ...] = Field(min_length=1, max_length=16)
    lead_s: float = Field(1.0, ge=0.0, le=10.0)
    """Trim held at the start so the record begins in trimmed flight (trim removal)."""

    @model_validator(mode="after")
    def _controls(self) -> Plan:
        unknown = {n for s in self.segments for n in s.signals} - set(CONTROLS)
        if unknown:
            raise ValueError(f"unknown control {sorted(unknown)}; controls are {CONTROLS}")
        return self

    def to_compact(self) -> dict:
        """The plan as plain values with defaults left out (the discriminators stay)."""
        data = self.model_dump(mode="json", exclude_defaults=True)
        for packed, segment in zip(data["segments"], self.segments, strict=True):
            for name, sig in segment.signals.items():
                packed["signals"][name]["kind"] = sig.kind
        return data

    def to_bytes(self) -> bytes:
        """Compact JSON (a file, or a preview of what the radio carries)."""
        return json.dumps(self.to_compact(), separators=(",", ":")).encode()

    @classmethod
    def from_bytes(cls, data: bytes) -> Plan:
        return cls.model_validate_json(data)

    def controls(self) -> list[str]:
        """Controls the plan moves, in CONTROLS order."""
        used = {n for s in self.segments for n in s.signals}
        return [c for c in CONTROLS if c in used]


@dataclass(frozen=True)
class Timeline:
    """A plan rendered at the command rate: sample i is commanded at start + i·dt."""

    plan: Plan
    dt: float
    values: dict[str, np.ndarray]
    """Per control, the deflection from trim at every sample (its unit)."""
    active: dict[str, np.ndarray] = field(repr=False)
    """Per control, True where one of its signals plays (not lead, not free response)."""

    @property
    def count(self) -> int:
        return len(next(iter(self.values.values())))

    @property
    def duration(self) -> float:
        return self.count * self.dt

    def times(self) -> np.ndarray:
        return np.arange(self.count) * self.dt


def render(plan: Plan, rate_hz: float) -> Timeline:
    """Every control's deflection from trim at rate_hz, lead and free response included."""
    dt = 1.0 / rate_hz
    pieces: dict[str, list[np.ndarray]] = {c: [] for c in plan.controls()}
    flags: dict[str, list[np.ndarray]] = {c: [] for c in plan.controls()}
    lead = round(plan.lead_s / dt)
    for c in pieces:
        pieces[c].append(np.zeros(lead))
        flags[c].append(np.zeros(lead, dtype=bool))
    for segment in plan.segments:
        played = {name: sig.samples(dt) for name, sig in segment.signals.items()}
        length = max(len(v) for v in played.values()) + round(segment.free_s / dt)
        for c in pieces:
            v = played.get(c, np.zeros(0))
            pieces[c].append(np.concatenate([v, np.zeros(length - len(v))]))
            flags[c].append(np.arange(length) < len(v))
    # A final sample at trim: the last command of every run is the trim itself.
    values = {c: np.concatenate([*p, [0.0]]) for c, p in pieces.items()}
    active = {c: np.concatenate([*f, [False]]) for c, f in flags.items()}
    return Timeline(plan, dt, values, active)


class PlanRefused(ValueError):
    """A plan that must not start; the message says which limit and by how much."""


def refusals(plan: Plan, rate_hz: float, surfaces: Mapping[str, Surface], envelope: Envelope):
    """Every reason this plan may not fly with this configuration (empty: it may)."""
    reasons = _cheap_refusals(plan, rate_hz, envelope)
    if reasons:  # refused before rendering: a typo must not cost a render of its size
        for segment in plan.segments:  # with every other reason, from the parameters
            for name, sig in segment.signals.items():
                if name not in surfaces:
                    reasons.append(f"{name} is not a configured control ([excitation.surfaces])")
                elif abs(sig.amplitude) > surfaces[name].max_amplitude + 1e-9:
                    unit = _unit(surfaces[name])
                    reasons.append(
                        f"{name}: {abs(sig.amplitude):.3g} {unit} from trim exceeds its "
                        f"max_amplitude of {surfaces[name].max_amplitude:g} {unit}"
                    )
        return list(dict.fromkeys(reasons))
    timeline = render(plan, rate_hz)
    if timeline.duration > envelope.max_duration_s:
        reasons.append(
            f"plan lasts {timeline.duration:.1f} s, longer than the envelope's "
            f"max_duration_s = {envelope.max_duration_s:g} s"
        )
    for name in plan.controls():
        if name not in surfaces:
            reasons.append(f"{name} is not a configured control ([excitation.surfaces])")
            continue
        surface, peak = surfaces[name], float(np.max(np.abs(timeline.values[name])))
        if peak > surface.max_amplitude + 1e-9:
            reasons.append(
                f"{name}: {peak:.3g} {_unit(surface)} from trim exceeds its max_amplitude of "
                f"{surface.max_amplitude:g} {_unit(surface)}"
            )
    return reasons


def played_s(sig) -> float:
    """How long a signal plays (s), from its parameters alone."""
    return sig.played_s if hasattr(sig, "played_s") else sig.duration_s


def planned_s(plan: Plan) -> float:
    """The plan's length (s) from its parameters alone, without rendering it (to within a
    command period per signal)."""
    return plan.lead_s + sum(
        max(played_s(sig) for sig in segment.signals.values()) + segment.free_s
        for segment in plan.segments
    )


def _cheap_refusals(plan: Plan, rate_hz: float, envelope: Envelope) -> list[str]:
    """What can be refused from the plan's parameters alone: frequencies at or above Nyquist,
    pulses shorter than a command period, a length beyond the envelope. A plan from the
    radio goes through these before it is rendered, so a typo (a harmonic of 1e6, a sweep
    from 1e-9 Hz with dwell cycles, a pulse of 1e-4 s) is refused at once."""
    reasons = _stray_controls(plan)
    nyquist, period = rate_hz / 2, 1.0 / rate_hz
    for segment in plan.segments:
        for name, sig in segment.signals.items():
            top = getattr(sig, "top_hz", 0.0)
            if top >= nyquist:
                reasons.append(
                    f"{name}: {sig.kind} reaches {top:g} Hz, not below the "
                    f"{nyquist:g} Hz Nyquist frequency of the {rate_hz:g} Hz command rate"
                )
            shortest = getattr(sig, "shortest_s", None)
            if shortest is not None and shortest < period:
                reasons.append(
                    f"{name}: {sig.kind} holds a level for {shortest:g} s, shorter than one "
                    f"command period ({period:g} s at {rate_hz:g} Hz)"
                )
    length = planned_s(plan)
    if length > envelope.max_duration_s + 2 * period * (1 + len(plan.segments)):
        reasons.append(
            f"plan lasts {length:.1f} s, longer than the envelope's "
            f"max_duration_s = {envelope.max_duration_s:g} s"
        )
    return reasons


def _stray_controls(plan: Plan) -> list[str]:
    """A control the plan's axis set does not identify (a lateral plan on the elevator): its
    response would enter the record with no input in the model to explain it, and it moves
    the other axis off its trim. Refused rather than warned: no run of one axis set wants it
    (docs/excitation.md)."""
    takes = AXIS_SETS[plan.axes][0]
    stray = [c for c in plan.controls() if c not in takes]
    if not stray:
        return []
    return [
        f"{', '.join(stray)}: not an input of the {plan.axes} model ({', '.join(takes)}), "
        f"so its response would be left unexplained in the fit; play only "
        f'{", ".join(takes)}, or fly the plan as axes "full"'
    ]


def check(plan: Plan, rate_hz: float, surfaces: Mapping[str, Surface], envelope: Envelope):
    """Raise PlanRefused listing every reason the plan may not fly; return its timeline."""
    reasons = refusals(plan, rate_hz, surfaces, envelope)
    if reasons:
        raise PlanRefused(f"plan {plan.id!r} refused: " + "; ".join(reasons))
    return render(plan, rate_hz)


def _unit(surface: Surface) -> str:
    return "%" if surface.unit == "percent" else "deg"


def summary(timeline: Timeline, surfaces: Mapping[str, Surface]) -> dict:
    """Duration, per-control RPF/peak/band, largest cross-correlation, servo warnings."""
    per_control = {}
    warnings: list[str] = []
    for name, values in timeline.values.items():
        played = values[timeline.active[name]]
        per_control[name] = {
            "rpf": signals.relative_peak_factor(played),
            "peak": float(np.max(np.abs(played))),
            "unit": _unit(surfaces[name]) if name in surfaces else None,
            "band_hz": list(power_band(played, timeline.dt)),
        }
        if name in surfaces:
            warnings += servo.distortion_warnings(name, values, timeline.dt, surfaces[name])
    return {
        "plan": timeline.plan.id,
        "axes": timeline.plan.axes,
        "rate_hz": 1.0 / timeline.dt,
        "duration_s": timeline.duration,
        "controls": per_control,
        "max_cross_correlation": max_cross_correlation(timeline.values),
        "warnings": warnings,
    }


def power_band(u: np.ndarray, dt: float, fraction: float = 0.98) -> tuple[float, float]:
    """Frequencies (Hz) between which the central `fraction` of the signal's power lies."""
    power = np.abs(np.fft.rfft(u - np.mean(u))) ** 2
    freqs = np.fft.rfftfreq(len(u), dt)
    cumulative = np.cumsum(power) / np.sum(power)
    tail = (1 - fraction) / 2
    lo = freqs[int(np.searchsorted(cumulative, tail))]
    hi = freqs[min(int(np.searchsorted(cumulative, 1 - tail)), len(freqs) - 1)]
    return float(lo), float(hi)


def max_cross_correlation(values: Mapping[str, np.ndarray]) -> float:
    """Largest |Σ uᵢuⱼ| / (‖uᵢ‖‖uⱼ‖) between two controls over the whole plan (0: orthogonal)."""
    names = list(values)
    worst = 0.0
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            x, y = values[a], values[b]
            norm = np.linalg.norm(x) * np.linalg.norm(y)
            if norm > 0:
                worst = max(worst, abs(float(x @ y)) / norm)
    return worst


# Preset defaults (documented in docs/excitation.md): amplitudes in degrees / percent from trim.
PRESET_AMPLITUDE = {"aileron": 4.0, "elevator": 3.0, "rudder": 4.0, "throttle": 10.0}
DOUBLET_PULSE_S = {"aileron": 1.0, "rudder": 1.0, "elevator": 0.5}
MULTISINE_PERIOD_S = 20.0
MULTISINE_PERIODS = 2.0
THROTTLE_LEVELS = (1.0, 1.0, -1.0)  # thesis figure 4.4: two counts up, one count down
THROTTLE_COUNT_S = 2.0
# The full preset: one period of FULL_PERIOD_S of multisines on all four controls at once, on
# odd harmonics only and each control on its own (orthogonal multisines, Morelli, J. Aircraft
# 40(2), 2003), the throttle below FULL_THROTTLE_TOP_HZ (the phugoid's band), the surfaces
# interleaved up to FULL_TOP_HZ. Why (measured on JSBSim's Cub, Cessna 182 and PA-28,
# docs/identification.md): a phugoid of 20–30 s needs a record of several periods and power at
# its frequency; and the lateral excitation drags the aircraft through sideslip (drag ∝ β²),
# an even-order effect that drives the phugoid. Even-order products of odd harmonics fall on
# even harmonics, and a multisine playing through the whole window turns their mean into a
# constant (DC) forcing, so neither biases the fit; the thesis's 2 × 20 s multisines followed
# by throttle steps switched that forcing on and off inside the record and gave a phugoid
# 30 % off on the Cessna even in calm air.
FULL_PERIOD_S = 80.0
FULL_THROTTLE_TOP_HZ = 0.12
FULL_TOP_HZ = 2.0


def full_harmonics(throttle: bool = True) -> dict[str, tuple[int, ...]]:
    """Odd harmonics of 1/FULL_PERIOD_S per control for the full preset (disjoint). Without a
    throttle (a glider) the elevator plays the throttle's low lines too: they are the
    phugoid's, and nothing else would put power in its band."""
    odd = range(1, round(FULL_TOP_HZ * FULL_PERIOD_S) + 1, 2)
    low = [k for k in odd if k / FULL_PERIOD_S < FULL_THROTTLE_TOP_HZ]
    rest = [k for k in odd if k / FULL_PERIOD_S >= FULL_THROTTLE_TOP_HZ]
    if not throttle:
        return {
            "elevator": tuple(sorted(low + rest[0::3])),
            "aileron": tuple(rest[1::3]),
            "rudder": tuple(rest[2::3]),
        }
    return {
        "throttle": tuple(low),
        "elevator": tuple(rest[0::3]),
        "aileron": tuple(rest[1::3]),
        "rudder": tuple(rest[2::3]),
    }


# The full preset's amplitudes: its multisine spreads the elevator's power over 25 lines, and at
# the doublet's ±3° the J-3 Cub's short period in light turbulence had a damping-ratio scatter
# of 1.7 % over seeds (4 of 10 within 10 %; make bench-jsbsim); at ±4.5°, 1.1 % (9 of 10), with
# no bias from the larger amplitude in calm air.
FULL_AMPLITUDE = {**PRESET_AMPLITUDE, "elevator": 4.5}


# Without a throttle the elevator plays the phugoid's lines, at this share of its amplitude
# until the sizing shapes them to the response (agent/sizing.py): an unpowered aircraft's
# phugoid is its least damped mode (ζ ≈ 1/(√2 L/D), about 0.03 for a glider of L/D 23), so
# a line near it moves the airspeed many times more than the same line elsewhere.
PHUGOID_LINES_GAIN = 0.25


# The controls each preset plays, the only ones it takes an amplitude for.
PRESET_CONTROLS = {
    "lateral": ("aileron", "rudder"),
    "longitudinal": ("elevator", "throttle"),
    "full": ("throttle", "elevator", "aileron", "rudder"),
}


def only(plan: Plan, controls: Iterable[str]) -> Plan:
    """`plan` without the signals of controls not in `controls` (an aircraft without them: a
    glider's throttle); a segment left with no signal is left out."""
    keep = set(controls)
    segments = []
    for segment in plan.segments:
        signals = {c: sig for c, sig in segment.signals.items() if c in keep}
        if signals:
            segments.append(segment.model_copy(update={"signals": signals}))
    if not segments:
        raise ValueError(
            f"plan {plan.id!r} plays none of {', '.join(sorted(keep)) or 'no'} controls"
        )
    return plan.model_copy(update={"segments": tuple(segments)})


def preset(
    name: str,
    amplitude: Mapping[str, float] | None = None,
    plan_id: str | None = None,
    controls: Iterable[str] | None = None,
):
    """The thesis's plans: lateral (aileron then rudder doublet), longitudinal (elevator
    doublet then throttle steps); and full: an 80 s odd-harmonic multisine on all four
    controls at once (see FULL_PERIOD_S; the thesis's figure 6.12 played multisines on the
    surfaces, then throttle steps). `controls`: the aircraft's (default all four); the
    others' signals are left out (`only`)."""
    controls = None if controls is None else tuple(controls)
    amp = {**(FULL_AMPLITUDE if name == "full" else PRESET_AMPLITUDE), **(amplitude or {})}
    plays = PRESET_CONTROLS.get(name, ())
    stray = [c for c in amplitude or {} if c not in plays]
    if plays and stray:  # a typo (ailron) must not leave the plan at its default amplitude
        raise ValueError(
            f"the {name} preset plays {', '.join(plays)}; no amplitude for "
            f"{', '.join(map(repr, stray))}"
        )

    def doublet(c: str) -> dict:
        return {c: Doublet(pulse_s=DOUBLET_PULSE_S[c], amplitude=amp[c])}

    steps = Steps(levels=THROTTLE_LEVELS, hold_s=THROTTLE_COUNT_S, amplitude=amp["throttle"])
    throttle = {"throttle": steps}
    if name == "lateral":
        segments = [
            Segment(signals=doublet("aileron"), free_s=4.0),
            Segment(signals=doublet("rudder"), free_s=6.0),
        ]
    elif name == "longitudinal":
        segments = [
            Segment(signals=doublet("elevator"), free_s=3.0),
            Segment(signals=throttle, free_s=10.0),
        ]
    elif name == "full":
        powered = controls is None or "throttle" in controls
        lines = full_harmonics(throttle=powered)
        shape = {} if powered else {"elevator": _phugoid_shape(lines["elevator"])}
        segments = [
            Segment(
                signals={
                    c: Multisine(
                        harmonics=h,
                        period_s=FULL_PERIOD_S,
                        periods=1,
                        amplitude=amp[c],
                        shape=shape.get(c, ()),
                    )
                    for c, h in lines.items()
                }
            )
        ]
    else:
        raise ValueError(f"unknown preset {name!r}; presets are {', '.join(PRESETS)}")
    plan = Plan(id=plan_id or name, axes=name, segments=tuple(segments))
    return plan if controls is None else only(plan, controls)


def _phugoid_shape(harmonics: tuple[int, ...]) -> tuple[tuple[float, float], ...]:
    """The elevator's shape without a throttle: its lines in the throttle's band (the
    phugoid's) at PHUGOID_LINES_GAIN, the rest at 1."""
    hz = [k / FULL_PERIOD_S for k in harmonics]
    low = max(f for f in hz if f < FULL_THROTTLE_TOP_HZ)
    high = min(f for f in hz if f >= FULL_THROTTLE_TOP_HZ)
    return ((low, PHUGOID_LINES_GAIN), (high, 1.0))


def _thesis_multisine(control: str, amplitude: float) -> Multisine:
    return Multisine(
        harmonics=signals.THESIS_HARMONICS[control],
        period_s=MULTISINE_PERIOD_S,
        periods=MULTISINE_PERIODS,
        amplitude=amplitude,
    )
