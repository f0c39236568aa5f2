"""Surface units ↔ PWM, and a servo model that says when a signal would be distorted.

The thesis saw a frequency sweep lose amplitude after 7 s because the servos could not follow
(§4.4.5.2, figure 4.7): a slew-rate limit and the travel each side of neutral explain that, so
a plan is checked against both before flight.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from agent.config import Surface

# A control that spends more than this share of a commanded level slewing to it is distorted:
# the thesis's sweeps lost amplitude so; a fast servo's short slew at a doublet's step is not.
DISTORTION = 0.2


def to_pwm(values: np.ndarray, trim_us: float, surface: Surface) -> np.ndarray:
    """PWM (µs, integers) = trim + direction × us_per_unit × value, clamped to the limits."""
    raw = _raw(values, trim_us, surface)
    return np.clip(np.rint(raw), surface.min_us, surface.max_us).astype(int)


def pwm_clamped(values: np.ndarray, trim_us: float, surface: Surface) -> int:
    """How many samples to_pwm would clamp at this trim."""
    raw = _raw(values, trim_us, surface)
    return int(np.count_nonzero((raw < surface.min_us) | (raw > surface.max_us)))


def _raw(values: np.ndarray, trim_us: float, surface: Surface) -> np.ndarray:
    if surface.direction is None:  # resolved by role in [excitation.surfaces]
        raise ValueError("a control's direction is unset outside [excitation.surfaces]")
    return trim_us + surface.direction * surface.us_per_unit * np.asarray(values, dtype=float)


def distortion_warnings(name: str, signal: np.ndarray, dt: float, surface: Surface) -> list[str]:
    """Warnings when the servo model cannot follow the signal (empty list: it can)."""
    signal = np.asarray(signal, dtype=float)
    peak = float(np.max(np.abs(signal), initial=0.0))
    if peak == 0.0:
        return []
    warnings = []
    unit = "%" if surface.unit == "percent" else "deg"
    if peak > surface.travel:
        first = int(np.argmax(np.abs(signal) > surface.travel)) * dt
        warnings.append(
            f"{name}: {peak:.3g} {unit} from trim exceeds the servo travel of "
            f"{surface.travel:g} {unit} (from t = {first:.2f} s, assuming trim at neutral)"
        )
    first = _slew_bound(signal, dt, surface.rate_limit)
    if first is not None:
        need = float(np.max(np.abs(np.diff(signal)))) / dt
        warnings.append(
            f"{name}: needs {need:.0f} {unit}/s, servo rate limit {surface.rate_limit:g} "
            f"{unit}/s: from t = {first:.2f} s the servo spends over "
            f"{DISTORTION:.0%} of a level slewing to it (amplitude and shape are lost)"
        )
    return warnings


def _slew_bound(signal: np.ndarray, dt: float, rate_limit: float) -> float | None:
    """First time (s) a change the servo cannot make in one sample takes it more than
    DISTORTION of the time until the next such change; None if never.

    A doublet's step that a fast servo makes in 0.04 s of a 1 s pulse passes; a sampled sweep
    whose every sample outruns the servo fails where it starts doing so.
    """
    delta = np.abs(np.diff(signal))
    jumps = np.flatnonzero(delta > rate_limit * dt * (1 + 1e-9)) + 1
    if jumps.size == 0:
        return None
    hold = np.diff(np.append(jumps, len(signal))) * dt
    slew = delta[jumps - 1] / rate_limit
    bad = slew > DISTORTION * hold
    return float(jumps[np.argmax(bad)] * dt) if bad.any() else None


def surface_pwm(
    values: Mapping[str, np.ndarray], trims: Mapping[str, float], surfaces: Mapping[str, Surface]
) -> dict[int, np.ndarray]:
    """Per RC channel, the PWM sequence for each control's values around its trim."""
    return {
        surfaces[name].channel: to_pwm(v, trims[name], surfaces[name]) for name, v in values.items()
    }
