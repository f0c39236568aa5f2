"""ArduPlane's roll and pitch gains designed from an identified model (`sysid tune`).

The controller is ArduPlane's own FBWA law (agent.fbwa: an angle loop through TCONST
around a rate loop of feed-forward, P and I, speed-scaled), so what is designed are its
parameters, by classical loop shaping on the identified plant with its actuator:

- the plant from ArduPlane's notional surface output (±45°) to the body rate and the angle:
  the model's continuous A, B with the surface it moves through the linkage (measured surface
  degrees per notional degree, from the servo mapping) and the rudder's KFF_RDDRMIX share of the
  aileron; the actuator a first-order servo lag and a pure delay (the servo's dead time, the
  loop's 50 Hz sample and hold);
- FF: the demanded rate is flown by the feed-forward alone in steady rolling (pitching): the
  inverse of the model's steady rate per notional degree with the attitude's gravity terms left
  out (the roll rate of a held aileron, not the spiral's). ArduPlane's AUTOTUNE measures the
  same ratio from stick steps (peak surface over peak rate, AP_AutoTune.cpp); PX4's
  fixed-wing autotune takes the inverse DC gain of its identified rate model
  (fw_autotune_attitude_control);
- P: the largest that leaves the rate loop, broken at the actuator, with its I, PHASE_TARGET
  of phase margin and GAIN_MARGIN_DB of gain margin: rate damping and disturbance rejection as
  far as the servo's lag and the delays allow (where ArduPlane's AUTOTUNE raises P until its slew
  detector sees an oscillation, which a slow servo hides: ArduPilot issue 17900);
- I: its zero INTEGRATOR_SEPARATION below the rate loop's crossover, or below the aircraft's
  own rate bandwidth where that is higher (a weak surface's P loop hovers near unity gain),
  within ArduPlane's range: it trims out a steady moment without eating the phase margin;
- TCONST: the target (ArduPlane's 0.5 s unless given), lengthened until 1/TCONST sits
  BANDWIDTH_SEPARATION below the bandwidth of the rate the aircraft flies for a demanded one
  (feed-forward and feedback together) and the whole loop, broken at the actuator, keeps the
  margins MIL-F-9490D asks of a flight-control loop (6 dB, 45°);
- RMAX: the rate the model flies with RATE_SHARE of the servo's travel, so that a step's rate
  demand does not saturate the surface (its flown response would then rest on the surface's
  authority each way, beyond any linear model); ArduPlane's AUTOTUNE sets it with TCONST.
- A linkage with more travel one way than the other (Actuator.even and knee, as a run measures
  them): the loop shaped and its margins kept through the stronger way, FF through the mean,
  RMAX through each way (the roll's from the weaker, the pitch's UP and DN each its own).

Predicted: each loop's margins and crossover, the attitude's disturbance-rejection bandwidth
(where the sensitivity |1/(1 + L)| reaches −3 dB) and a step's rise time and overshoot, from the
model flown with agent.fbwa's laws at 50 Hz (a ±20° bank step, a ±5° pitch step; each way
through the linkage where its travel differs).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.interpolate
import scipy.linalg
import scipy.signal

from agent.excitation import follow
from agent.fbwa import DEFAULTS, LOOP_HZ, TRAVEL_DEG, Fbwa, G, Sensed

# Loop-shaping targets: the rate loop's phase margin (the attitude loop closed around it then
# keeps 45°), every loop's gain margin, and the whole loop's phase margin (MIL-F-9490D).
PHASE_TARGET = 60.0
GAIN_MARGIN_DB = 6.0
PHASE_MARGIN = 45.0
# The integrator's zero this many times below the rate loop's crossover.
INTEGRATOR_SEPARATION = 5.0
# The attitude loop's crossover at least this many times below the rate loop's.
BANDWIDTH_SEPARATION = 3.0
# Where no TCONST keeps the whole loop's margins, P is multiplied by BACKOFF, at most
# BACKOFFS times.
BACKOFF, BACKOFFS = 0.8, 12
# ArduPlane's own bounds on the rate gains it takes (its parameter ranges): a design outside
# them is refused, never clipped into a different design.
P_RANGE, I_RANGE, FF_RANGE = (0.001, 4.0), (0.0, 4.0), (0.01, 4.0)
TCONST_RANGE = (0.2, 2.0)
# The rate limit (RLL2SRV_RMAX, PTCH2SRV_RMAX_UP/DN, deg/s): the rate the aircraft flies with
# RATE_SHARE of the servo's travel, so that the feed-forward of the largest rate the loop asks
# for leaves the other half to the feedback, the trim and the air. Without it an attitude step
# asks 20°/TCONST and the surface saturates: the response then rests on the surface's
# authority each way, which no linear model holds (JSBSim's C172R, ailerons 15° up and 20°
# down: a −20° step 23 % slower than +20°; at about this share, within 9 % of the prediction
# both ways, benchmarks/tune_check.py). ArduPlane's own AUTOTUNE sets RMAX with TCONST
# (AP_AutoTune.cpp's tuning_table); its ranges here are ArduPlane's.
RATE_SHARE = 0.45
RMAX_RANGE = {"roll": (0.0, 180.0), "pitch": (0.0, 100.0)}
RMAX_NAMES = {"roll": ("RLL2SRV_RMAX",), "pitch": ("PTCH2SRV_RMAX_UP", "PTCH2SRV_RMAX_DN")}
# The yaw damper (`design_yaw`): the Dutch roll damping ratio it aims at (a common
# yaw-damper goal, well above MIL-F-8785C's Level 1 minimum of 0.19 for flight phase A), the
# least it must add to be turned on, and ArduPlane's range of YAW2SRV_DAMP; its high-pass
# (AP_YawController's 0.9960080 per 50 Hz sample).
DUTCH_ROLL_TARGET = 0.4
DUTCH_ROLL_GAIN = 0.05
DAMP_RANGE = (0.0, 2.0)
YAW_HIGH_PASS_RAD_S = 0.2
# The step each axis is predicted and checked for (the flight test): degrees.
STEPS = {"roll": 20.0, "pitch": 5.0}
FREQUENCIES = np.logspace(-2, 3, 4000)  # rad/s


class TuneError(ValueError):
    """The model cannot be tuned for (a missing channel, an unstable loop): why, in words."""


@dataclass(frozen=True, kw_only=True)
class Actuator:
    """Notional ArduPlane degrees to measured surface degrees: `link` per degree, through a
    first-order lag `lag_s` and a dead time `delay_s`; `even` per |degree − knee| beside it
    (the linkage's even part, agent.excitation.follow): a surface with more travel one way than
    the other (differential ailerons, an elevator with more up than down) moves link + even
    per degree above the `knee` (notional degrees from trim) and link − even below it."""

    link: float
    lag_s: float = 0.05
    delay_s: float = 0.02
    even: float = 0.0
    knee: float = 0.0

    def way(self, sign: float) -> float:
        """Measured surface units per notional degree on this side of the knee."""
        return self.link + (self.even if sign >= 0 else -self.even)

    def moved(self, output: float) -> float:
        """The measured surface's change from trim for a notional output (degrees from trim)."""
        return float(follow.moved(output, self.link, self.even, self.knee))

    @property
    def strongest(self) -> Actuator:
        """The same servo through the linkage's stronger direction: the loop's gain is the
        largest there, so the loop is shaped and its margins kept on it (the weaker direction
        then has more margin, and flies slower: `predicted_step` each way)."""
        up, down = self.way(1), self.way(-1)
        return replace(self, link=up if abs(up) >= abs(down) else down, even=0.0)

    def response(self, w: np.ndarray) -> np.ndarray:
        s = 1j * w
        return self.link * np.exp(-s * self.delay_s) / (1 + s * self.lag_s)


@dataclass(frozen=True, kw_only=True)
class Plant:
    """One axis: ẋ = A x + B u (u: the measured surfaces the notional output moves, as a
    column), the rate and angle as rows of C (rad/s, rad)."""

    A: np.ndarray
    B: np.ndarray  # (n,)
    rate: np.ndarray  # (n,)
    angle: np.ndarray  # (n,)
    steady: np.ndarray  # (n,) the states of the steady-rate response (attitude left out)

    def response(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rate, angle) in deg/s and deg per measured surface unit at `w`."""
        n = self.A.shape[0]
        X = np.array([np.linalg.solve(1j * wk * np.eye(n) - self.A, self.B) for wk in w])
        deg = 180.0 / np.pi
        return deg * (X @ self.rate), deg * (X @ self.angle)

    def steady_rate(self) -> float:
        """Steady rate (deg/s) per unit of input with the attitude's gravity terms left out."""
        keep = self.steady
        A, B = self.A[np.ix_(keep, keep)], self.B[keep]
        try:
            x = -np.linalg.solve(A, B)
        except np.linalg.LinAlgError:
            raise TuneError("the rate has no steady value (a singular model)") from None
        return float(np.degrees(self.rate[keep] @ x))


@dataclass(frozen=True, kw_only=True)
class Margins:
    gain_db: float  # inf: the phase never reaches −180°
    phase_deg: float
    crossover_rad_s: float
    rejection_rad_s: float | None = None  # |1/(1 + L)| reaches −3 dB
    delay_margin_s: float | None = None  # more delay the closed loop stays stable with


@dataclass(frozen=True, kw_only=True)
class AxisTune:
    """One axis's designed gains (ArduPlane's parameter names), what they replace, and what
    they predict."""

    axis: str
    params: dict[str, float]
    rate_loop: Margins
    attitude_loop: Margins
    step_deg: float
    rise_s: float
    overshoot_pct: float
    down: tuple[float, float] | None = None
    """(rise s, overshoot %) of the step the other way where the linkage's travel differs each
    way (Actuator.even); None: the same as the positive step's."""
    notes: tuple[str, ...] = ()

    def each_way(self) -> dict[str, tuple[float, float]]:
        """The predicted step's (rise s, overshoot %) by its sign, "+" and "−"."""
        up = (self.rise_s, self.overshoot_pct)
        return {"+": up, "−": self.down or up}


def margins(L: np.ndarray, w: np.ndarray = FREQUENCIES) -> Margins:
    """Gain and phase margins of a loop transfer L(jw): the phase margin at the highest gain
    crossover, the gain margin the smallest at any −180° crossing (negative: unstable)."""
    mag = np.abs(L)
    phase = np.degrees(np.unwrap(np.angle(L)))
    cross = np.flatnonzero((mag[:-1] >= 1) & (mag[1:] < 1))
    if cross.size == 0:
        raise TuneError("the loop never crosses unity gain: no crossover to shape")
    k = cross[-1]
    wc = float(np.interp(0.0, -np.log([mag[k], mag[k + 1]]), w[k : k + 2]))
    phase_c = float(np.interp(wc, w[k : k + 2], phase[k : k + 2]))
    pm = (180.0 + phase_c + 180.0) % 360.0 - 180.0  # 180° + the phase, within [−180°, 180°)
    wrapped = (phase + 180.0) % 360.0 - 180.0
    flips = np.flatnonzero(np.abs(np.diff(wrapped)) > 180.0)  # the phase passes ±180°
    gm = min((-20 * np.log10(mag[j]) for j in flips if mag[j] > 0), default=np.inf)
    return Margins(gain_db=float(gm), phase_deg=float(pm), crossover_rad_s=wc)


def _bandwidth(T: np.ndarray, w: np.ndarray = FREQUENCIES) -> float:
    """The highest frequency (rad/s) where the flown rate is within 3 dB of the demanded one:
    |T| ≥ −3 dB. (Its low-frequency end is the bank's and the spiral's, not the loop's.)"""
    within = np.flatnonzero(np.abs(T) >= 10 ** (-3 / 20))
    if within.size == 0:
        raise TuneError("the flown rate never comes within 3 dB of the demanded one")
    return float(w[within[-1]])


def _rejection(L: np.ndarray, w: np.ndarray = FREQUENCIES) -> float | None:
    sensitivity = np.abs(1.0 / (1.0 + L))
    above = np.flatnonzero(sensitivity >= 10 ** (-3 / 20))
    return float(w[above[0]]) if above.size else None


def design_axis(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    *,
    eas: float,
    eas2tas: float = 1.0,
    scaling_speed: float,
    tconst: float | None = None,
) -> AxisTune:
    """Design one axis's FF, P, I and TCONST (module docstring) at equivalent airspeed `eas`."""
    prefix, tc_name = (
        ("RLL_RATE", "RLL2SRV_TCONST")
        if axis == "roll"
        else (
            "PTCH_RATE",
            "PTCH2SRV_TCONST",
        )
    )
    S = float(np.clip(scaling_speed / eas, 0.1, 10.0))
    w = FREQUENCIES
    rate, angle = plant.response(w)
    # The loop shaped on the linkage's stronger direction (its margins hold both ways), the
    # feed-forward on its mean (what the steady rate takes on average over both).
    strong = actuator.strongest
    act = strong.response(w)
    Gr, Ga = rate * act, angle * act
    k_ss = plant.steady_rate() * actuator.link
    if not np.isfinite(k_ss) or k_ss <= 0:
        raise TuneError(
            f"{axis}: the model's steady rate per notional degree is {k_ss:.3g} (deg/s): the "
            "surface's linkage sign or the model is wrong for this axis"
        )
    if actuator.way(1) * actuator.way(-1) <= 0:
        raise TuneError(
            f"{axis}: the linkage's even part ({actuator.even:.3g} per degree) is as large as "
            f"its gain ({actuator.link:.3g}): the surface would not move one way"
        )
    ff = eas2tas / (S * k_ss)
    if ff > FF_RANGE[1]:
        # FF·S is what flies: a larger SCALING_SPEED takes the same surface with less FF.
        needed = scaling_speed * ff / FF_RANGE[1] * 1.1
        raise TuneError(
            f"{axis}: {prefix}_FF {ff:.3g} is beyond ArduPlane's {FF_RANGE[1]:g} at "
            f"SCALING_SPEED {scaling_speed:.1f}: the surface moves the aircraft too little for "
            f"that scaling; give SCALING_SPEED {needed:.0f} (FF scales with its inverse) or "
            "more of the servo's travel to the surface"
        )
    notes: list[str] = []
    dt = 1.0 / LOOP_HZ
    hold = np.exp(-1j * w * dt * 1.5)  # a sample's wait and the hold's half
    fltt = DEFAULTS[f"{prefix}_FLTT"]
    target = 1.0 / (1.0 + 1j * w / (2 * np.pi * fltt))

    def rate_loop(kp: float, ki: float) -> np.ndarray:
        return S * S * (kp + ki / (1j * w)) * Gr * hold

    # The aircraft's own rate response to the feed-forward (the roll mode's, the short
    # period's): its bandwidth places the integrator's zero where the feedback has none.
    own = _bandwidth(ff * S / eas2tas * target * Gr * hold)

    def integral(kp: float) -> float:
        """I for this P: its zero INTEGRATOR_SEPARATION below the P loop's crossover, or below
        the aircraft's own rate bandwidth where the P loop does not cross above it (a weak
        surface: P alone is near unity gain over the whole band)."""
        loop = rate_loop(kp, 0.0)
        crossing = margins(loop).crossover_rad_s if np.max(np.abs(loop)) >= 1.0 else 0.0
        return min(kp * max(crossing, own) / INTEGRATOR_SEPARATION, I_RANGE[1])

    def meets(kp: float) -> bool:
        return _meets(rate_loop(kp, integral(kp)), PHASE_TARGET)

    # P: the largest whose loop, with its I, keeps PHASE_TARGET and GAIN_MARGIN_DB (bisection
    # on log P).
    low, high = np.log(P_RANGE[0]), np.log(P_RANGE[1])
    if not meets(np.exp(low)):
        raise TuneError(f"{axis}: even P = {P_RANGE[0]} leaves the rate loop below its margins")
    if meets(np.exp(high)):
        low = high
        notes.append(f"P at ArduPlane's top of range {P_RANGE[1]}")
    for _ in range(40):
        mid = 0.5 * (low + high)
        if meets(np.exp(mid)):
            low = mid
        else:
            high = mid
    kp = float(np.exp(low))

    def whole(tc: float, kp: float, ki: float) -> np.ndarray:
        """The loop broken at the actuator: u = (FF + PID) F_T r_d + PID (F_T r_d − ω)'s
        feedback, r_d = −angle / TCONST."""
        pid = S * S * (kp + ki / (1j * w))
        forward = ff * S / eas2tas
        return ((forward + pid) * target * Ga / tc + pid * Gr) * hold

    def robust(tc: float, kp: float, ki: float) -> Margins | None:
        """The whole loop's margins (closed-loop eigenvalues, `loop_margins`), None when
        it misses MIL-F-9490D's."""
        law = Law(tc=tc, ff=ff * S / eas2tas, kp=S * S * kp, ki=S * S * ki, fltt=fltt)
        m = loop_margins(plant, strong, law, whole(tc, kp, ki))
        ok = m.gain_db >= GAIN_MARGIN_DB and m.phase_deg >= PHASE_MARGIN
        return m if ok else None

    # TCONST: the target, lengthened for bandwidth separation and the whole loop's margins;
    # where no TCONST in range keeps them, P (and its I) backs off: the rate loop's own
    # margins do not guarantee the whole loop's.
    attitude = None
    for _ in range(BACKOFFS):
        ki = integral(kp)
        pid = S * S * (kp + ki / (1j * w))
        # The rate the aircraft flies for a demanded one: the feed-forward's open path and the
        # feedback's, closed; its bandwidth (−3 dB) is what the attitude loop rides on.
        flown = (ff * S / eas2tas + pid) * target * Gr * hold / (1 + pid * Gr * hold)
        rate_bandwidth = _bandwidth(flown)
        tau = DEFAULTS[tc_name] if tconst is None else float(tconst)
        tau = max(tau, BANDWIDTH_SEPARATION / rate_bandwidth)
        attitude = robust(tau, kp, ki)
        while attitude is None and tau < TCONST_RANGE[1]:
            tau *= 1.1
            attitude = robust(tau, kp, ki)
        if attitude is not None:
            break
        kp *= BACKOFF
    if attitude is None:
        raise TuneError(f"{axis}: no TCONST up to {TCONST_RANGE[1]} s keeps the loop's margins")
    if kp < float(np.exp(low)) * 0.999:
        notes.append(f"P backed off to {kp:.3g} for the whole loop's margins")
    if ki >= I_RANGE[1]:  # a lower integrator zero still trims; ArduPlane takes no more
        notes.append(f"I at ArduPlane's top of range {I_RANGE[1]}: its zero lower still")
    final = rate_loop(kp, ki)
    if np.max(np.abs(final)) < 1.0:  # P alone never reaches unity: no crossover to report
        rate_margins = Margins(gain_db=np.inf, phase_deg=np.inf, crossover_rad_s=np.nan)
    else:
        rate_margins = margins(final)
    if tconst is not None and tau > tconst * 1.0001:
        notes.append(
            f"TCONST {tau:.2f} s, not {tconst:g}: the rate the aircraft flies (bandwidth "
            f"{rate_bandwidth:.1f} rad/s) cannot carry a faster attitude loop"
        )
    params = {
        tc_name: round(tau, 3),
        f"{prefix}_FF": round(ff, 4),
        f"{prefix}_P": round(kp, 4),
        f"{prefix}_I": round(ki, 4),
        f"{prefix}_D": 0.0,
    }
    for name, (lo, hi) in (
        (f"{prefix}_FF", FF_RANGE),
        (f"{prefix}_P", P_RANGE),
        (f"{prefix}_I", I_RANGE),
    ):
        if not lo <= params[name] <= hi:
            raise TuneError(f"{axis}: {name} {params[name]:.4g} outside ArduPlane's {lo}–{hi}")
    params |= rate_limits(axis, plant, actuator)
    step = STEPS[axis]
    rise, overshoot = predicted_step(axis, plant, actuator, params, eas, eas2tas, scaling_speed)
    down = None
    if actuator.even:
        down = predicted_step(axis, plant, actuator, params, eas, eas2tas, scaling_speed, sign=-1)
    return AxisTune(
        axis=axis,
        params=params,
        rate_loop=rate_margins,
        attitude_loop=attitude,
        step_deg=step,
        rise_s=rise,
        overshoot_pct=overshoot,
        down=down,
        notes=tuple(notes),
    )


def rate_limits(axis: str, plant: Plant, actuator: Actuator) -> dict[str, float]:
    """RMAX (deg/s, whole: ArduPlane's are integers): the rate the model flies with RATE_SHARE
    of the servo's travel, through the linkage each way (a positive output rolls right and
    pitches up where the steady rate is positive): the roll's one limit from the weaker
    direction, the pitch's UP and DN each from its own."""
    steady = plant.steady_rate()
    output = RATE_SHARE * TRAVEL_DEG

    def limit(sign: int) -> float:
        rate = steady * sign * actuator.moved(sign * output)
        return float(np.clip(math.floor(rate), *RMAX_RANGE[axis]))

    if axis == "roll":
        return {"RLL2SRV_RMAX": min(limit(1), limit(-1))}
    return {"PTCH2SRV_RMAX_UP": limit(1), "PTCH2SRV_RMAX_DN": limit(-1)}


@dataclass(frozen=True, kw_only=True)
class Assessed:
    """A given set of one axis's gains on the model: its loops' margins and a step's
    response (None where the step does not settle: the set does not fly that axis)."""

    rate_loop: Margins
    attitude_loop: Margins
    rise_s: float | None
    overshoot_pct: float | None
    down: tuple[float, float] | None = None
    """The step the other way where the linkage's travel differs (AxisTune.down)."""

    def sound(self) -> bool:
        """Whether the whole loop keeps MIL-F-9490D's margins (GAIN_MARGIN_DB, PHASE_MARGIN)."""
        m = self.attitude_loop
        return bool(m.gain_db >= GAIN_MARGIN_DB and m.phase_deg >= PHASE_MARGIN)


def _names(axis: str) -> tuple[str, str]:
    """The rate loop's parameter prefix and the time constant's name of an axis."""
    return ("RLL_RATE", "RLL2SRV_TCONST") if axis == "roll" else ("PTCH_RATE", "PTCH2SRV_TCONST")


def loops(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    params: Mapping[str, float],
    *,
    eas: float,
    scaling_speed: float,
    eas2tas: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The rate loop and the whole loop, each broken at the actuator (through its linkage's
    stronger direction), over FREQUENCIES, for a set of one axis's gains (those missing at
    ArduPlane's defaults)."""
    prefix, tc_name = _names(axis)
    value = {**DEFAULTS, **dict(params)}
    S = float(np.clip(scaling_speed / eas, 0.1, 10.0))
    w = FREQUENCIES
    rate, angle = plant.response(w)
    act = actuator.strongest.response(w)
    Gr, Ga = rate * act, angle * act
    hold = np.exp(-1j * w * (1.0 / LOOP_HZ) * 1.5)
    target = 1.0 / (1.0 + 1j * w / (2 * np.pi * value[f"{prefix}_FLTT"]))
    ff, kp, ki = (float(value[f"{prefix}_{k}"]) for k in ("FF", "P", "I"))
    pid = S * S * (kp + ki / (1j * w))
    whole = ((ff * S / eas2tas + pid) * target * Ga / float(value[tc_name]) + pid * Gr) * hold
    return pid * Gr * hold, whole


def assess(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    params: Mapping[str, float],
    *,
    eas: float,
    scaling_speed: float,
    eas2tas: float = 1.0,
) -> Assessed:
    """Any set of one axis's FBWA gains (ArduPlane's names; those missing at its defaults)
    on the plant: the gains a design would replace, or a step on the way to it."""
    prefix, tc_name = _names(axis)
    value = {**DEFAULTS, **dict(params)}
    S = float(np.clip(scaling_speed / eas, 0.1, 10.0))
    rate_loop, whole = loops(
        axis, plant, actuator, value, eas=eas, scaling_speed=scaling_speed, eas2tas=eas2tas
    )
    fltt = value[f"{prefix}_FLTT"]
    ff, kp, ki = (float(value[f"{prefix}_{k}"]) for k in ("FF", "P", "I"))
    tc = float(value[tc_name])
    law = Law(tc=tc, ff=ff * S / eas2tas, kp=S * S * kp, ki=S * S * ki, fltt=fltt)
    if np.max(np.abs(rate_loop)) < 1.0:
        rate_margins = Margins(gain_db=np.inf, phase_deg=np.inf, crossover_rad_s=np.nan)
    else:
        try:
            rate_margins = margins(rate_loop)
        except TuneError:
            rate_margins = Margins(gain_db=-np.inf, phase_deg=-np.inf, crossover_rad_s=np.nan)
    attitude = loop_margins(plant, actuator.strongest, law, whole)
    try:
        rise, overshoot = predicted_step(axis, plant, actuator, value, eas, eas2tas, scaling_speed)
    except TuneError:
        rise = overshoot = None
    down = None
    if actuator.even and rise is not None:
        try:
            down = predicted_step(
                axis, plant, actuator, value, eas, eas2tas, scaling_speed, sign=-1
            )
        except TuneError:  # one way does not settle: the set does not fly the axis
            rise = overshoot = None
    return Assessed(
        rate_loop=rate_margins,
        attitude_loop=attitude,
        rise_s=rise,
        overshoot_pct=overshoot,
        down=down,
    )


@dataclass(frozen=True)
class Law:
    """FBWA's law about the trim, linear (its clipping aside), in degrees: u = ff·r_f +
    kp (r_f − ω) + I, İ = ki (r_f − ω), ṙ_f = 2π fltt (r_d − r_f), r_d = −angle / tc (the
    speed scaler folded into ff, kp, ki)."""

    tc: float
    ff: float
    kp: float
    ki: float
    fltt: float


def _pade(delay: float, order: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A delay as a state-space Padé approximant (A, B, C, D)."""
    if delay <= 0:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), 1.0
    num, den = scipy.interpolate.pade(
        [(-delay) ** k / math.factorial(k) for k in range(2 * order + 1)], order
    )
    A, B, C, D = scipy.signal.tf2ss(num.coeffs, den.coeffs)
    return A, B, C, float(np.squeeze(D))


def closed_loop(
    plant: Plant, actuator: Actuator, law: Law, gain: float = 1.0, extra_delay: float = 0.0
) -> np.ndarray:
    """The closed loop's state matrix: plant, servo lag, the dead time and the 50 Hz loop's
    wait and hold (1.5 samples, Padé), the law's target filter and integrator; the loop's gain
    times `gain` and `extra_delay` s more delay at the actuator (its margins)."""
    deg = 180.0 / np.pi
    n = plant.A.shape[0]
    Ap, Bp, Cp, Dp = _pade(actuator.delay_s + 1.5 / LOOP_HZ + extra_delay)
    d = Ap.shape[0]
    # states: plant x (n), surface δ (1), delay z (d), r_f (1), I (1)
    size = n + 1 + d + 2
    M = np.zeros((size, size))
    ix, iδ, iz, ir, iI = slice(0, n), n, slice(n + 1, n + 1 + d), n + 1 + d, n + 2 + d
    rate = deg * plant.rate
    angle = deg * plant.angle
    # u = ff r_f + kp (r_f − rate·x) + I  (a row over the states)
    u = np.zeros(size)
    u[ir] = law.ff + law.kp
    u[ix] = -law.kp * rate
    u[iI] = 1.0
    u *= gain
    M[ix, ix] = plant.A
    M[ix, iδ] = plant.B
    _servo(M, u, (Ap, Bp, Cp, Dp), iz, iδ, actuator)
    wt = 2 * np.pi * law.fltt
    M[ir, ix] = -wt * angle / law.tc
    M[ir, ir] = -wt
    M[iI, ir] = law.ki
    M[iI, ix] = -law.ki * rate
    return M


def damper_loop(
    roll: Plant,
    roll_actuator: Actuator,
    law: Law,
    rudder: Plant,
    rudder_actuator: Actuator,
    *,
    damp: float,
    scaler: float,
    eas: float,
    turn: float = 1.0,
    gain: float = 1.0,
    extra_delay: float = 0.0,
) -> np.ndarray:
    """The lateral closed loop with the yaw damper: the roll loop (`closed_loop`, the rudder's
    KFF_RDDRMIX share of the aileron folded into `roll`'s B) and, on the rudder's own servo
    (lag, dead time and the loop's 1.5 samples, Padé), AP_YawController's damper linearised:
    rudder = −DAMP·S²·HP(deg(r − g/EAS·φ·YAW2SRV_RLL)), HP = s/(s + YAW_HIGH_PASS_RAD_S).
    `rudder`: the same states, the rudder's B and the yaw rate as its rate row. `gain` and
    `extra_delay` as `closed_loop`'s, on the damper's path only (its margins)."""
    base = closed_loop(roll, roll_actuator, law)
    n, N = roll.A.shape[0], base.shape[0]
    Ap, Bp, Cp, Dp = _pade(rudder_actuator.delay_s + 1.5 / LOOP_HZ + extra_delay)
    d = Ap.shape[0]
    size = N + 1 + 1 + d  # + the high-pass state, the rudder δ, its delay
    ih, iδ, iz = N, N + 1, slice(N + 2, N + 2 + d)
    M = np.zeros((size, size))
    M[:N, :N] = base
    deg = 180.0 / np.pi
    signal = np.zeros(size)  # the damper's input, deg/s, as a row over the states
    signal[:n] = deg * (rudder.rate - G / eas * turn * roll.angle)
    a = YAW_HIGH_PASS_RAD_S
    M[ih, :] += a * signal
    M[ih, ih] -= a
    command = -damp * scaler * scaler * gain * signal  # on y = signal − x_h
    command[ih] += damp * scaler * scaler * gain
    _servo(M, command, (Ap, Bp, Cp, Dp), iz, iδ, rudder_actuator)
    M[:n, iδ] += rudder.B
    return M


def _servo(M: np.ndarray, command: np.ndarray, pade, iz: slice, iδ: int, actuator: Actuator):
    """Into M: `command` (a row over the states) through the delay's Padé states `iz` (its
    output y_d = C z + D u) and the servo's first-order lag onto the surface state `iδ`."""
    Ap, Bp, Cp, Dp = pade
    d = Ap.shape[0]
    if d:
        M[iz, :] += np.outer(Bp[:, 0], command)
        M[iz, iz] += Ap
    delayed = Dp * command
    if d:
        delayed = delayed.copy()
        delayed[iz] += Cp[0]
    lag = max(actuator.lag_s, 1e-3)
    # A linear loop through the linkage's stronger direction: its margins hold both ways.
    M[iδ, :] += actuator.strongest.link * delayed / lag
    M[iδ, iδ] -= 1.0 / lag


def dutch_roll(values: np.ndarray, near: complex) -> complex:
    """The eigenvalue of `values` (upper half plane) nearest the Dutch roll `near`."""
    upper = [v for v in values if v.imag > 0]
    if not upper:
        return complex(np.nan, np.nan)
    return complex(min(upper, key=lambda v: abs(v - near)))


@dataclass(frozen=True, kw_only=True)
class YawTune:
    """The yaw damper's gain and what it predicts: the Dutch roll without and with it, and
    the factor on the damper's gain the loop stands before it goes unstable (dB)."""

    params: dict[str, float]
    before: complex
    after: complex
    gain_margin_db: float
    notes: tuple[str, ...] = ()

    @staticmethod
    def zeta(value: complex) -> float:
        return float(-value.real / abs(value)) if abs(value) > 0 else float("nan")


def design_yaw(
    roll: Plant,
    roll_actuator: Actuator,
    law: Law,
    rudder: Plant,
    rudder_actuator: Actuator,
    *,
    scaler: float,
    eas: float,
) -> YawTune:
    """YAW2SRV_DAMP: the smallest that brings the Dutch roll's damping ratio, with the roll
    loop closed, to DUTCH_ROLL_TARGET while the damper's path keeps GAIN_MARGIN_DB (twice the
    gain still stable), within ArduPlane's DAMP_RANGE; where none reaches it, the one of most
    damping that keeps the margin, if it adds DUTCH_ROLL_GAIN at least; 0 (ArduPlane's
    default: off) where the aircraft's own damping already reaches the target or the damper
    adds too little."""
    kw = {"scaler": scaler, "eas": eas}
    base = closed_loop(roll, roll_actuator, law)
    fixed = _untouched(roll)
    pairs = [v for v in np.linalg.eigvals(roll.A) if v.imag > 1e-6]
    if not pairs:
        raise TuneError("yaw: the model has no Dutch roll (no oscillatory lateral mode)")
    # The Dutch roll is the lateral plant's oscillatory mode; with the roll loop closed, the
    # closed loop's nearest to it.
    near = complex(max(pairs, key=lambda v: v.imag))
    before = dutch_roll(np.linalg.eigvals(base), near)

    def loop(damp: float, gain: float = 1.0) -> np.ndarray:
        return damper_loop(
            roll, roll_actuator, law, rudder, rudder_actuator, damp=damp, gain=gain, **kw
        )

    def margin(damp: float) -> float:
        """dB of gain on the damper's path before instability (at most 40)."""
        low, high = 0.0, 40.0
        if _stable(loop(damp, 10 ** (high / 20)), fixed):
            return high
        for _ in range(30):
            mid = 0.5 * (low + high)
            if _stable(loop(damp, 10 ** (mid / 20)), fixed):
                low = mid
            else:
                high = mid
        return low

    zeta0 = YawTune.zeta(before)
    name = "YAW2SRV_DAMP"
    if zeta0 >= DUTCH_ROLL_TARGET:
        note = (
            f"the Dutch roll's own damping ratio {zeta0:.2f} reaches {DUTCH_ROLL_TARGET}: no damper"
        )
        return YawTune(
            params={name: 0.0}, before=before, after=before, gain_margin_db=np.inf, notes=(note,)
        )
    best = None
    for damp in np.geomspace(0.01, DAMP_RANGE[1], 80):
        M = loop(float(damp))
        if not _stable(M, fixed):
            break
        after = dutch_roll(np.linalg.eigvals(M), before)
        if not np.isfinite(after.real) or margin(float(damp)) < GAIN_MARGIN_DB:
            break
        z = YawTune.zeta(after)
        if best is None or z > best[1] + 1e-9:
            best = (float(damp), z, after)
        if z >= DUTCH_ROLL_TARGET:
            break
    if best is None or best[1] < zeta0 + DUTCH_ROLL_GAIN:
        note = (
            f"the damper adds too little to the Dutch roll's damping ratio {zeta0:.2f} within "
            f"{GAIN_MARGIN_DB:g} dB: left off"
        )
        return YawTune(
            params={name: 0.0}, before=before, after=before, gain_margin_db=np.inf, notes=(note,)
        )
    damp, z, after = best
    notes = ()
    if z < DUTCH_ROLL_TARGET:
        notes = (
            f"Dutch roll damping ratio {z:.2f}, short of {DUTCH_ROLL_TARGET}: the most "
            "the margin allows",
        )
    return YawTune(
        params={name: round(damp, 4)},
        before=before,
        after=after,
        gain_margin_db=margin(damp),
        notes=notes,
    )


def _untouched(plant: Plant) -> np.ndarray:
    """The plant's eigenvalues whose modes the axis's surface does not move (the other axis's
    in a decoupled model, an engine's): the loop cannot move them either, so its stability is
    judged without them."""
    values, vectors = np.linalg.eig(plant.A)
    try:
        left = np.linalg.inv(vectors)
    except np.linalg.LinAlgError:
        return np.zeros(0, dtype=complex)
    reach = np.abs(left @ plant.B) * np.linalg.norm(vectors, axis=0)
    return values[reach < 1e-9 * max(np.linalg.norm(plant.B), 1e-300)]


def _stable(M: np.ndarray, untouched: np.ndarray | None = None) -> bool:
    """Every eigenvalue of M in the left half plane, but those of `untouched` modes."""
    if not np.all(np.isfinite(M)):
        return False
    values = list(np.linalg.eigvals(M))
    for fixed in () if untouched is None else untouched:
        if not values:
            break
        k = int(np.argmin([abs(v - fixed) for v in values]))
        if abs(values[k] - fixed) <= 1e-6 * (1 + abs(fixed)):
            values.pop(k)
    return bool(max((v.real for v in values), default=-1.0) < 0)


def loop_margins(plant: Plant, actuator: Actuator, law: Law, L: np.ndarray) -> Margins:
    """The whole loop's margins from the closed loop's eigenvalues: the gain factor either way
    (dB, the smaller) and the extra delay it takes before it goes unstable, the delay given as
    the phase it is at the loop's crossover (the highest of L's, FREQUENCIES); closed-loop
    eigenvalues rather than a Bode reading, because the loop crosses unity more than once
    and its plant can be unstable (a divergent spiral), where a Bode plot's margins mislead."""
    fixed = _untouched(plant)
    if not _stable(closed_loop(plant, actuator, law), fixed):
        return Margins(gain_db=-np.inf, phase_deg=-np.inf, crossover_rad_s=np.nan)
    gains = []
    for direction in (1.0, -1.0):
        low, high = 0.0, 40.0  # dB
        if _stable(closed_loop(plant, actuator, law, 10 ** (direction * high / 20)), fixed):
            gains.append(high)
            continue
        for _ in range(30):
            mid = 0.5 * (low + high)
            if _stable(closed_loop(plant, actuator, law, 10 ** (direction * mid / 20)), fixed):
                low = mid
            else:
                high = mid
        gains.append(low)
    mag = np.abs(L)
    crossings = np.flatnonzero((mag[:-1] >= 1) & (mag[1:] < 1))
    wc = float(FREQUENCIES[crossings[-1]]) if crossings.size else np.nan
    low, high = 0.0, 2.0  # s
    if _stable(closed_loop(plant, actuator, law, extra_delay=high), fixed):
        low = high
    else:
        for _ in range(30):
            mid = 0.5 * (low + high)
            if _stable(closed_loop(plant, actuator, law, extra_delay=mid), fixed):
                low = mid
            else:
                high = mid
    phase = float(np.degrees(low * wc)) if np.isfinite(wc) else np.inf
    return Margins(
        gain_db=float(min(gains)),
        phase_deg=phase,
        crossover_rad_s=wc,
        rejection_rad_s=_rejection(L),
        delay_margin_s=float(low),
    )


def scaling_for(plant: Plant, actuator: Actuator, eas: float, eas2tas: float = 1.0) -> float:
    """The SCALING_SPEED (m/s) at which this axis's FF is a tenth inside ArduPlane's range:
    FF = EAS2TAS / (S · steady rate), S = SCALING_SPEED / EAS, so a weak surface (a glider's
    aileron) takes a larger SCALING_SPEED rather than an FF beyond the range."""
    k_ss = plant.steady_rate() * actuator.link
    if not np.isfinite(k_ss) or k_ss <= 0:
        return eas
    return float(eas * eas2tas * 1.1 / (FF_RANGE[1] * k_ss))


def _meets(L: np.ndarray, phase: float) -> bool:
    """L keeps `phase` of phase margin and GAIN_MARGIN_DB (a loop below unity gain everywhere
    does: it never crosses)."""
    if np.max(np.abs(L)) < 1.0:
        return True
    try:
        m = margins(L)
    except TuneError:
        return False
    return m.phase_deg >= phase and m.gain_db >= GAIN_MARGIN_DB


def step_trace(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    params: Mapping[str, float],
    eas: float,
    eas2tas: float,
    scaling_speed: float,
    seconds: float = 6.0,
    sign: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """STEPS[axis] (`sign`: that way) flown by agent.fbwa's laws with these parameters on the
    linear plant and the actuator (its linkage each way), 1 kHz inside the 50 Hz loop: (time
    s, the angle's change in the step's direction, deg)."""
    fbwa = Fbwa({**dict(params), "SCALING_SPEED": scaling_speed})
    fbwa.scaler = float(np.clip(scaling_speed / eas, *(_scaler_limits(fbwa.params, scaling_speed))))
    h = 1e-3
    per_loop = round(1.0 / (LOOP_HZ * h))
    n = plant.A.shape[0]
    Ad = scipy.linalg.expm(plant.A * h)
    Bd = (
        np.linalg.solve(plant.A, (Ad - np.eye(n)) @ plant.B)
        if _invertible(plant.A)
        else (h * plant.B)
    )
    x = np.zeros(n)
    surface = 0.0
    queue = [0.0] * max(1, round(actuator.delay_s / h))
    step = sign * STEPS[axis]
    angles = []
    command = 0.0
    for k in range(round(seconds / h)):
        if k % per_loop == 0:
            rate = float(plant.rate @ x)
            ang = float(plant.angle @ x)
            if axis == "roll":
                s = Sensed(phi=ang, theta=0.0, p=rate, q=0.0, r=0.0, eas=eas, eas2tas=eas2tas)
                out = fbwa.step(s, roll_deg=step, pitch_deg=0.0)
                command = out.aileron
            else:
                s = Sensed(phi=0.0, theta=ang, p=0.0, q=rate, r=0.0, eas=eas, eas2tas=eas2tas)
                out = fbwa.step(s, roll_deg=0.0, pitch_deg=step)
                command = out.elevator
        queue.append(command)
        delayed = queue.pop(0)
        surface += (
            h / actuator.lag_s * (delayed - surface) if actuator.lag_s > 0 else (delayed - surface)
        )
        x = Ad @ x + Bd * actuator.moved(surface)
        angles.append(sign * np.degrees(float(plant.angle @ x)))
    angles = np.asarray(angles)
    t = np.arange(angles.size) * h
    return t, angles


def predicted_step(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    params: Mapping[str, float],
    eas: float,
    eas2tas: float,
    scaling_speed: float,
    seconds: float = 6.0,
    sign: int = 1,
) -> tuple[float, float]:
    """(10–90 % rise time s, overshoot %) of STEPS[axis] (`sign`: that way) flown by
    agent.fbwa's laws with these parameters on the linear plant and actuator (`step_trace`)."""
    t, angles = step_trace(
        axis, plant, actuator, params, eas, eas2tas, scaling_speed, seconds, sign
    )
    h = float(t[1] - t[0])
    step = STEPS[axis]
    final = angles[-round(0.5 / h) :].mean()
    if not np.isfinite(final) or abs(final) < 0.5 * step:
        raise TuneError(f"{axis}: the predicted step does not settle near {step:g}°")
    rise = float(t[np.argmax(angles >= 0.9 * final)] - t[np.argmax(angles >= 0.1 * final)])
    overshoot = float(max(0.0, (angles.max() - final) / final * 100.0))
    return rise, overshoot


def _scaler_limits(params: Mapping[str, float], scaling_speed: float) -> tuple[float, float]:
    as_min = max(params["AIRSPEED_MIN"], 5.0)
    low = min(0.5, scaling_speed / (2 * params["AIRSPEED_MAX"]))
    return low, max(2.0, scaling_speed / (0.7 * as_min))


def _invertible(A: np.ndarray) -> bool:
    return bool(np.linalg.cond(A) < 1e12)


def axis_plant(
    model: Mapping[str, Sequence],
    inputs: Sequence[str],
    outputs: Sequence[str],
    *,
    surface: str,
    rate: str,
    angle: str,
    axis_outputs: Sequence[str],
    slow: Sequence[str] = (),
    mix: Mapping[str, float] | None = None,
) -> Plant:
    """The plant of one axis from a continuous model ({"A", "B", "C"} in output coordinates:
    a state per output, then any engine lags): the states of `axis_outputs` (the axis's own:
    the other axis and the engine, at fixed throttle, left out, as the whole-aircraft method
    decouples them), `surface` driven, plus each input of `mix` at that share of it (measured
    units per unit of the surface: the rudder's KFF_RDDRMIX share of the aileron, through both
    linkages); `slow`: the states left out of the steady rate (the attitude angle; the
    airspeed, whose change belongs to the phugoid: the pitch rate of the short period, the
    roll rate of the roll mode with the sideslip and yaw settled)."""
    missing = [c for c in (surface, rate, angle) if c not in (*inputs, *outputs)]
    missing += [c for c in axis_outputs if c not in outputs and c not in missing]
    if missing:
        raise TuneError(f"the model has no {', '.join(missing)}: it cannot tune this axis")
    A, B, C = (np.asarray(model[k], dtype=float) for k in ("A", "B", "C"))
    b = B[:, list(inputs).index(surface)].copy()
    for other, share in (mix or {}).items():
        if other in inputs:
            b = b + share * B[:, list(inputs).index(other)]
    state = {name: int(np.argmax(np.abs(C[list(outputs).index(name)]))) for name in outputs}
    keep = [state[name] for name in axis_outputs]
    rows = np.eye(len(keep))
    names = list(axis_outputs)
    return Plant(
        A=A[np.ix_(keep, keep)],
        B=b[keep],
        rate=rows[names.index(rate)],
        angle=rows[names.index(angle)],
        steady=np.array([i for i, name in enumerate(names) if name not in slow]),
    )


def notional_link(direction: int, us_per_unit: float, servo_half_range_us: float) -> float:
    """Measured surface units per ArduPlane notional degree: ±45° of output is
    ±`servo_half_range_us` (SERVOn_MIN/MAX about TRIM: 400 µs at ArduPilot's defaults, the
    installation's [excitation.surfaces] min_us/max_us where set up to use the servo's whole
    travel), and the surface moves a unit per `direction` × `us_per_unit` µs."""
    return servo_half_range_us / TRAVEL_DEG / (direction * us_per_unit)


def param_file(tunes: Sequence[AxisTune], header: Sequence[str] = ()) -> str:
    """ArduPilot's .param format: NAME,VALUE per line, comments after #."""
    lines = [f"# {line}" for line in header]
    for tune in tunes:
        lines += [f"{name},{value:g}" for name, value in tune.params.items()]
    return "\n".join(lines) + "\n"


# The axes designed: (surface, rate, angle, the surfaces mixed in at a share of it by the
# parameter named, the axis's own states).
AXES = {
    "roll": ("aileron", "p", "phi", {"rudder": "KFF_RDDRMIX"}, ("beta", "p", "r", "phi")),
    "pitch": ("elevator", "q", "theta", {}, ("airspeed", "alpha", "q", "theta")),
}
# The servo's lag and dead time where nothing measured them (s): a small hobby servo.
SERVO_LAG_S, SERVO_DELAY_S = 0.05, 0.02


@dataclass(frozen=True, kw_only=True)
class Model:
    """An identified model as the design takes it: continuous A, B, C in output coordinates
    (a state per output, then any engine lags) and its trim outputs by channel."""

    id: str
    inputs: Sequence[str]
    outputs: Sequence[str]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    trim: Mapping[str, float]


@dataclass(frozen=True, kw_only=True)
class Options:
    """What the design takes beside the model: each surface's linkage given (measured surface
    per commanded degree; wins over `measured`), each surface's linkage and lag a run measured
    ({"gain", "lag_s", "even", "knee"}: the execution log's, agent.excitation.follow; "even"
    the linkage's travel per |commanded degree − knee| beside "gain", more one way of the
    knee than the other), the
    servo's lag and dead time given, the target time constants, and SCALING_SPEED (default: the
    trim airspeed, raised where FF needs)."""

    linkage: Mapping[str, float] = field(default_factory=dict)
    measured: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    servo_lag_s: float | None = None
    delay_s: float | None = None
    roll_tconst: float | None = None
    pitch_tconst: float | None = None
    scaling_speed: float | None = None


@dataclass(frozen=True, kw_only=True)
class Design:
    """The gains of every axis that could be designed, why the others could not, and notes."""

    model_id: str
    eas: float  # the trim airspeed designed at (m/s)
    scaling_speed: float
    tunes: tuple[AxisTune, ...]
    refused: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    loops: Mapping[str, tuple[Plant, Actuator]] = field(default_factory=dict)
    """Each designed axis's plant and actuator (to assess other gains on: `assess`, `toward`)."""
    yaw: YawTune | None = None
    """The yaw damper, designed with the roll loop closed (None: no rudder, or no roll)."""

    def params(self) -> dict[str, float]:
        """Every designed parameter by ArduPlane's name, SCALING_SPEED too."""
        out = {name: value for t in self.tunes for name, value in t.params.items()}
        if self.yaw is not None:
            out.update(self.yaw.params)
        out["SCALING_SPEED"] = round(self.scaling_speed, 1)
        return out


def design(model: Model, channels, surfaces: Mapping, options: Options | None = None) -> Design:
    """Each axis of `AXES` designed from `model` (`design_axis`), with the channels' names
    (agent.config.Channels) and the surfaces' PWM mapping (agent.config.Surface by role);
    TuneError where nothing could be designed, or the trim airspeed is unknown and no
    SCALING_SPEED given."""
    options = options or Options()
    names = {
        role: getattr(channels, role)
        for role in ("airspeed", "alpha", "q", "theta", "beta", "p", "r", "phi")
    }
    airspeed = model.trim.get(channels.airspeed)
    if options.scaling_speed is None and airspeed is None:
        raise TuneError(f"{model.id}: the model has no trim airspeed: give SCALING_SPEED")
    eas = float(airspeed if airspeed is not None else options.scaling_speed)
    cont = {"A": model.A, "B": model.B, "C": model.C}
    refused, axes = [], []
    for axis, (surface, rate, angle, mixed, states) in AXES.items():
        channel = getattr(channels, surface)
        setup = surfaces.get(surface)
        if channel not in model.inputs or setup is None or setup.direction is None:
            refused.append(f"{axis}: the model has no {surface} input")
            continue
        actuator = _actuator(surface, setup, options)
        link = actuator.link
        mix = {}
        for other, param in mixed.items():
            other_setup = surfaces.get(other)
            if other_setup is None or other_setup.direction is None:
                continue
            if getattr(channels, other) in model.inputs:
                mix[getattr(channels, other)] = (
                    DEFAULTS[param] * _actuator(other, other_setup, options).link / link
                )
        try:
            plant = axis_plant(
                cont,
                model.inputs,
                model.outputs,
                surface=channel,
                rate=names[rate],
                angle=names[angle],
                axis_outputs=[names[role] for role in states],
                slow=(names["phi"], names["theta"], names["airspeed"]),
                mix=mix,
            )
        except TuneError as exc:
            refused.append(str(exc))
            continue
        axes.append((axis, plant, actuator))
    # SCALING_SPEED: given, else the trim airspeed, raised where an axis's FF would not fit
    # ArduPlane's range at it (one value for both axes: ArduPlane has one).
    scaling, notes = options.scaling_speed, []
    if scaling is None:
        scaling = max([eas, *(scaling_for(p, a, eas) for _, p, a in axes)])
        if scaling > eas * 1.0001:
            notes.append(
                f"SCALING_SPEED {scaling:.1f} m/s, above the trim's {eas:.1f}: a surface too "
                "weak for ArduPlane's FF range at the trim's"
            )
    tunes = []
    for axis, plant, actuator in axes:
        try:
            tconst = options.roll_tconst if axis == "roll" else options.pitch_tconst
            tunes.append(
                design_axis(axis, plant, actuator, eas=eas, scaling_speed=scaling, tconst=tconst)
            )
        except TuneError as exc:
            refused.append(str(exc))
    if not tunes:
        raise TuneError("; ".join(refused) or "nothing to tune")
    yaw = None
    roll = next((t for t in tunes if t.axis == "roll"), None)
    loops = {axis: (plant, actuator) for axis, plant, actuator in axes}
    if roll is not None:
        try:
            yaw = _yaw(model, channels, surfaces, options, roll, loops["roll"], eas, scaling)
        except TuneError as exc:
            refused.append(str(exc))
    return Design(
        model_id=model.id,
        eas=eas,
        scaling_speed=scaling,
        tunes=tuple(tunes),
        refused=tuple(refused),
        notes=tuple(notes),
        loops=loops,
        yaw=yaw,
    )


def _yaw(model, channels, surfaces, options, roll, loop, eas, scaling) -> YawTune | None:
    """The yaw damper (`design_yaw`) around the designed roll loop; None without a rudder."""
    setup = surfaces.get("rudder")
    channel = channels.rudder
    if channel not in model.inputs or setup is None or setup.direction is None:
        return None
    names = {
        role: getattr(channels, role) for role in ("beta", "p", "r", "phi", "theta", "airspeed")
    }
    rudder = axis_plant(
        {"A": model.A, "B": model.B, "C": model.C},
        model.inputs,
        model.outputs,
        surface=channel,
        rate=names["r"],
        angle=names["phi"],
        axis_outputs=[names[r] for r in AXES["roll"][4]],
    )
    actuator = _actuator("rudder", setup, options)
    S = float(np.clip(scaling / eas, 0.1, 10.0))
    p = roll.params
    law = Law(
        tc=p["RLL2SRV_TCONST"],
        ff=p["RLL_RATE_FF"] * S,
        kp=S * S * p["RLL_RATE_P"],
        ki=S * S * p["RLL_RATE_I"],
        fltt=DEFAULTS["RLL_RATE_FLTT"],
    )
    plant, roll_actuator = loop
    return design_yaw(plant, roll_actuator, law, rudder, actuator, scaler=S, eas=eas)


def _actuator(surface: str, setup, options: Options) -> Actuator:
    """A surface's actuator for the design: its linkage given, else as a run measured it (with
    its even part: the travel each way), else the servo mapping's alone; the lag a run measured
    as a dead time (the best correlation's), else a small hobby servo's; the servo's lag and
    dead time given win."""
    measured = options.measured.get(surface, {})
    given = options.linkage.get(surface)
    shape = {} if given is not None else measured  # a given linkage is taken straight
    lag = measured.get("lag_s")
    servo, delay = options.servo_lag_s, options.delay_s
    per_degree = surface_link(setup, None)  # plan units per notional degree
    return Actuator(
        link=surface_link(setup, given if given is not None else measured.get("gain")),
        lag_s=servo if servo is not None else SERVO_LAG_S if lag is None else 0.0,
        delay_s=delay if delay is not None else SERVO_DELAY_S if lag is None else lag,
        even=abs(per_degree) * float(shape.get("even", 0.0)),
        knee=float(shape.get("knee", 0.0)) / per_degree,
    )


def surface_link(setup, linkage: float | None) -> float:
    """Measured surface units per notional degree through a surface's servo mapping and its
    linkage (1 where none is known)."""
    half = (setup.max_us - setup.min_us) / 2
    return notional_link(setup.direction, setup.us_per_unit, half) * (
        1.0 if linkage is None else linkage
    )


# The steps tried toward a design when the largest the step limit allows misses the margins,
# as shares of that largest.
STEP_TRIES = (1.0, 0.75, 0.5, 0.25)
# Each axis's gains a proposal moves, by ArduPlane's names.
AXIS_GAINS = {
    "roll": ("RLL2SRV_TCONST", "RLL_RATE_FF", "RLL_RATE_P", "RLL_RATE_I", "RLL_RATE_D"),
    "pitch": ("PTCH2SRV_TCONST", "PTCH_RATE_FF", "PTCH_RATE_P", "PTCH_RATE_I", "PTCH_RATE_D"),
}
RANGES = {"TCONST": TCONST_RANGE, "FF": FF_RANGE, "P": P_RANGE, "I": I_RANGE, "D": (0.0, 1.0)}


@dataclass(frozen=True, kw_only=True)
class Step:
    """One axis's gains as a proposal sets them: the design, or the largest step toward it
    that the step limit allows and that keeps the margins; the share of the way (1: the
    design), and its assessment. `params` empty: no step keeps the margins."""

    axis: str
    params: dict[str, float]
    share: float
    assessed: Assessed | None
    why: str = ""


def toward(
    axis: str,
    plant: Plant,
    actuator: Actuator,
    current: Mapping[str, float],
    designed: Mapping[str, float],
    *,
    eas: float,
    scaling_speed: float,
    max_step: float,
) -> Step:
    """The designed gains of `axis`, or a step toward them from `current` where one gain would
    change by more than `max_step` times (either way): every gain moves the same share of the
    way on a log scale (a gain from or to zero, linearly), the share the largest the limit
    allows; a set of gains half-way between two sound ones need not be sound, so it is
    assessed and, where it misses the margins, shorter steps are tried (STEP_TRIES). Each gain
    within ArduPlane's range (RANGES)."""
    names = [n for n in AXIS_GAINS[axis] if n in designed]
    # The rate limit is not a gain scaled toward its design: the designed one is what keeps
    # the steps' surface within its authority, whatever share of the way the gains go.
    limits = {n: float(designed[n]) for n in RMAX_NAMES[axis] if n in designed}
    limit = 1.0
    for n in names:
        c, d = float(current.get(n, DEFAULTS[n])), float(designed[n])
        if c > 0 and d > 0 and not math.isclose(c, d):
            limit = min(limit, math.log(max_step) / abs(math.log(d / c)))
        elif c > 0 and d <= 0:
            limit = min(limit, 1.0 - 1.0 / max_step)

    def at(share: float) -> dict[str, float]:
        out = {}
        for n in names:
            c, d = float(current.get(n, DEFAULTS[n])), float(designed[n])
            v = c * (d / c) ** share if c > 0 and d > 0 else c + share * (d - c)
            lo, hi = RANGES[n.rsplit("_", 1)[-1]]
            out[n] = round(float(np.clip(v, lo, hi)), 4)
        return out | limits

    for k in STEP_TRIES:
        share = limit * k
        params = at(share)
        checked = assess(axis, plant, actuator, params, eas=eas, scaling_speed=scaling_speed)
        if checked.sound():
            return Step(axis=axis, params=params, share=share, assessed=checked)
    return Step(
        axis=axis,
        params={},
        share=0.0,
        assessed=None,
        why=(
            f"{axis}: no step within ×{max_step:g} of the current gains keeps the whole loop's "
            f"{GAIN_MARGIN_DB:g} dB and {PHASE_MARGIN:g}°"
        ),
    )
