"""ArduPlane's stabilised flight (FBWA): its roll, pitch and yaw laws, as ArduPlane 4.5/4.6 runs
them, for the emulated autopilot.

Taken from ArduPilot's source (facts, not code): libraries/APM_Control/AP_FW_Controller.cpp
(the rate loop shared by roll and pitch), AP_RollController.cpp and AP_PitchController.cpp
(angle error to rate demand, the pitch's turn coordination and their parameter tables),
AP_YawController.cpp (the yaw damper), libraries/AC_PID/AC_PID.cpp (update_all: the target,
error and derivative filters, the integrator and its limit), ArduPlane/Attitude.cpp
(calc_speed_scaler, stabilize_roll/pitch/yaw, the rudder mix), ArduPlane/mode_fbwa.cpp and
ArduPlane/altitude.cpp (the sticks to the attitude demand; the scaler's 2 Hz filter at 10 Hz).

Per loop (ArduPlane's 50 Hz):
- speed scaler S = SCALING_SPEED / EAS, within [min(0.5, SCALING_SPEED / (2 AIRSPEED_MAX)),
  max(2, SCALING_SPEED / (0.7 max(AIRSPEED_MIN, 5)))], low-passed at 2 Hz every 0.1 s;
- roll: rate demand r = (φ_d − φ) / RLL2SRV_TCONST (deg/s), within ±RLL2SRV_RMAX when set;
  pitch: r = (θ_d − θ) / PTCH2SRV_TCONST + the turn's pitch rate
  cos θ |g tan φ sin φ / TAS| · PTCH2SRV_RLL (φ within ±80°), within RMAX_UP / RMAX_DN;
- the rate loop: the AC_PID fed target and gyro rate in rad/s times S², its P, I, D in
  degrees of surface, its feed-forward FF·target divided by S·EAS2TAS (so the feed-forward
  scales with 1/speed and the error terms with 1/speed², as a surface's moment does with
  dynamic pressure); the output within ±45°. The integrator may only shrink while the last
  output reached ±45°, and stands still below the axis's minimum airspeed (roll AIRSPEED_MIN,
  pitch half of it);
- yaw: rudder = the damper (off at ArduPlane's default YAW2SRV_DAMP = 0) + KFF_RDDRMIX times
  the aileron + the pilot's rudder.

Surfaces are in ArduPlane's notional degrees (±45° full travel: the servo output's ±4500
centidegrees); the autopilot maps them to PWM by SERVOn_MIN/TRIM/MAX. Left out: the P+D slew
limiter (RLL_RATE_SMAX; at ArduPlane's default gains in normal flight its modifier is 1),
input shaping (off by default), inverted flight, the ground's integrator reset, stall
prevention's roll limit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

G = 9.80665
# ArduPlane's defaults (its parameter tables), by parameter name.
DEFAULTS: dict[str, float] = {
    "RLL2SRV_TCONST": 0.5,
    "RLL2SRV_RMAX": 0.0,
    "RLL_RATE_P": 0.08,
    "RLL_RATE_I": 0.15,
    "RLL_RATE_D": 0.0,
    "RLL_RATE_FF": 0.345,
    "RLL_RATE_IMAX": 0.666,
    "RLL_RATE_FLTT": 3.0,
    "RLL_RATE_FLTE": 0.0,
    "RLL_RATE_FLTD": 12.0,
    "PTCH2SRV_TCONST": 0.5,
    "PTCH2SRV_RMAX_UP": 0.0,
    "PTCH2SRV_RMAX_DN": 0.0,
    "PTCH2SRV_RLL": 1.0,
    "PTCH_RATE_P": 0.04,
    "PTCH_RATE_I": 0.15,
    "PTCH_RATE_D": 0.0,
    "PTCH_RATE_FF": 0.345,
    "PTCH_RATE_IMAX": 0.666,
    "PTCH_RATE_FLTT": 3.0,
    "PTCH_RATE_FLTE": 0.0,
    "PTCH_RATE_FLTD": 12.0,
    "YAW2SRV_DAMP": 0.0,
    "YAW2SRV_INT": 0.0,
    "YAW2SRV_SLIP": 0.0,
    "YAW2SRV_RLL": 1.0,
    "YAW2SRV_IMAX": 1500.0,
    "KFF_RDDRMIX": 0.5,
    "SCALING_SPEED": 15.0,
    "AIRSPEED_MIN": 9.0,
    "AIRSPEED_MAX": 22.0,
    "ROLL_LIMIT_DEG": 45.0,
    "PTCH_LIM_MAX_DEG": 20.0,
    "PTCH_LIM_MIN_DEG": -25.0,
    "PTCH_TRIM_DEG": 0.0,
    "STAB_PITCH_DOWN": 2.0,
    "TRIM_THROTTLE": 45.0,
}
# ArduPlane's main loop (SCHED_LOOP_RATE's default for Plane) and the scaler's update.
LOOP_HZ = 50.0
SCALER_PERIOD_S = 0.1
SCALER_FILTER_HZ = 2.0
# Full travel of a surface output, degrees (±4500 centidegrees).
TRAVEL_DEG = 45.0
# The yaw damper's high-pass filter, per sample (AP_YawController: ≈ 0.2 rad/s at 50 Hz).
YAW_HIGH_PASS = 0.9960080


def lowpass_alpha(dt: float, hz: float) -> float:
    """ArduPilot's calc_lowpass_alpha_dt: a first-order filter's gain per step (1 if off)."""
    if hz <= 0:
        return 1.0
    if dt <= 0:
        return 0.0
    return dt / (dt + 1.0 / (2 * np.pi * hz))


@dataclass
class Pid:
    """AC_PID's update_all for a rate loop: the target low-passed at FLTT, the error at FLTE,
    its derivative at FLTD; the integrator within ±IMAX, only shrinking when `limit`."""

    kp: float
    ki: float
    kd: float
    kff: float
    imax: float
    fltt: float
    flte: float
    fltd: float
    target: float = 0.0
    error: float = 0.0
    derivative: float = 0.0
    integrator: float = 0.0
    fresh: bool = True

    def update(self, target: float, measured: float, dt: float, limit: bool):
        """(P, I, D, FF) for one step, in the loop's units (rad/s scaled)."""
        if not (np.isfinite(target) and np.isfinite(measured)):
            return 0.0, self.integrator, 0.0, 0.0
        if self.fresh:
            self.target, self.error, self.derivative = target, target - measured, 0.0
            self.fresh = False
        else:
            last = self.error
            self.target += lowpass_alpha(dt, self.fltt) * (target - self.target)
            self.error += lowpass_alpha(dt, self.flte) * ((self.target - measured) - self.error)
            if dt > 0:
                rate = (self.error - last) / dt
                self.derivative += lowpass_alpha(dt, self.fltd) * (rate - self.derivative)
        if self.ki <= 0 or dt <= 0:
            self.integrator = 0.0
        elif not limit or self.integrator * self.error < 0:
            self.integrator += self.error * self.ki * dt
            self.integrator = float(np.clip(self.integrator, -self.imax, self.imax))
        return (
            self.error * self.kp,
            self.integrator,
            self.derivative * self.kd,
            self.target * self.kff,
        )

    def reset(self) -> None:
        self.integrator, self.fresh = 0.0, True


@dataclass
class RateLoop:
    """AP_FW_Controller's rate loop of one axis: surface degrees from a rate demand."""

    pid: Pid
    last_out: float = 0.0

    def step(
        self,
        rate_dps: float,
        scaler: float,
        gyro: float,
        dt: float,
        eas2tas: float,
        underspeed: bool,
    ) -> float:
        """The surface (deg, within ±TRAVEL_DEG) for demand `rate_dps` (deg/s) and the measured
        body rate `gyro` (rad/s)."""
        limit = abs(self.last_out) >= TRAVEL_DEG or underspeed
        held = self.pid.integrator
        p, i, d, ff = self.pid.update(np.radians(rate_dps) * scaler**2, gyro * scaler**2, dt, limit)
        if underspeed:
            self.pid.integrator = i = float(np.clip(held, -self.pid.imax, self.pid.imax))
        out = np.degrees(ff / (scaler * eas2tas) + p + i + d)
        self.last_out = float(out)
        return float(np.clip(out, -TRAVEL_DEG, TRAVEL_DEG))


def _pid(params: Mapping[str, float], prefix: str) -> Pid:
    return Pid(
        kp=params[f"{prefix}_P"],
        ki=params[f"{prefix}_I"],
        kd=params[f"{prefix}_D"],
        kff=params[f"{prefix}_FF"],
        imax=params[f"{prefix}_IMAX"],
        fltt=params[f"{prefix}_FLTT"],
        flte=params[f"{prefix}_FLTE"],
        fltd=params[f"{prefix}_FLTD"],
    )


@dataclass(frozen=True, kw_only=True)
class Sensed:
    """What the laws read: attitude (rad), body rates (rad/s), equivalent airspeed (m/s), its
    ratio to true airspeed, and the lateral acceleration (m/s²)."""

    phi: float
    theta: float
    p: float
    q: float
    r: float
    eas: float
    eas2tas: float = 1.0
    ay: float = 0.0


@dataclass(frozen=True, kw_only=True)
class Surfaces:
    """The laws' outputs, notional degrees (±TRAVEL_DEG), and the attitude they asked for."""

    aileron: float
    elevator: float
    rudder: float
    roll_demand_deg: float
    pitch_demand_deg: float


@dataclass
class Fbwa:
    """FBWA's laws with ArduPlane's parameters (`params`, by name; DEFAULTS where not given).
    `step` is one 50 Hz loop; a parameter changed by name (`set`) acts from the next step."""

    params: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = set(self.params) - set(DEFAULTS)
        if unknown:
            raise KeyError(f"not an FBWA parameter: {', '.join(sorted(unknown))}")
        self.params = DEFAULTS | dict(self.params)
        self.roll = RateLoop(_pid(self.params, "RLL_RATE"))
        self.pitch = RateLoop(_pid(self.params, "PTCH_RATE"))
        self.scaler = 1.0
        self._scaler_clock = 0.0
        self._yaw_in = self._yaw_out = self._yaw_integrator = 0.0
        self._yaw_damp_last = self.params["YAW2SRV_DAMP"]
        self._yaw_last_out = 0.0

    def set(self, name: str, value: float) -> None:
        """Set a parameter as PARAM_SET does (KeyError: no such parameter here)."""
        if name not in DEFAULTS:
            raise KeyError(name)
        self.params[name] = float(value)
        for loop, prefix in ((self.roll, "RLL_RATE"), (self.pitch, "PTCH_RATE")):
            fresh = _pid(self.params, prefix)
            for attr in ("kp", "ki", "kd", "kff", "imax", "fltt", "flte", "fltd"):
                setattr(loop.pid, attr, getattr(fresh, attr))

    def demands(self, roll_stick: float, pitch_stick: float, theta: float, phi: float):
        """The attitude demand (deg) from the sticks (−1…1, FBWA: no deadzone): roll within
        ROLL_LIMIT_DEG cos θ, pitch up to PTCH_LIM_MAX_DEG and down to PTCH_LIM_MIN_DEG |cos φ|."""
        p = self.params
        roll_limit = p["ROLL_LIMIT_DEG"] * np.cos(theta)
        roll = float(np.clip(roll_stick, -1, 1)) * roll_limit
        pitch_min = p["PTCH_LIM_MIN_DEG"] * abs(np.cos(phi))
        stick = float(np.clip(pitch_stick, -1, 1))
        pitch = stick * p["PTCH_LIM_MAX_DEG"] if stick > 0 else -stick * pitch_min
        return roll, float(np.clip(pitch, pitch_min, p["PTCH_LIM_MAX_DEG"]))

    def _update_scaler(self, eas: float, dt: float) -> None:
        p = self.params
        self._scaler_clock += dt
        if self._scaler_clock + 1e-9 < SCALER_PERIOD_S:
            return
        self._scaler_clock = 0.0
        as_min = max(p["AIRSPEED_MIN"], 5.0)
        low = min(0.5, p["SCALING_SPEED"] / (2 * p["AIRSPEED_MAX"]))
        high = max(2.0, p["SCALING_SPEED"] / (0.7 * as_min))
        target = p["SCALING_SPEED"] / eas if eas > 1e-4 else high
        target = float(np.clip(target, low, high))
        self.scaler += lowpass_alpha(SCALER_PERIOD_S, SCALER_FILTER_HZ) * (target - self.scaler)

    def step(
        self,
        s: Sensed,
        *,
        roll_deg: float,
        pitch_deg: float,
        rudder_stick: float = 0.0,
        dt: float = 1.0 / LOOP_HZ,
    ) -> Surfaces:
        """One loop: the surfaces for the attitude demand (`roll_deg`, `pitch_deg`) and the
        pilot's rudder (−1…1), from what the aircraft senses."""
        p = self.params
        self._update_scaler(s.eas, dt)
        S = self.scaler
        tau = max(p["RLL2SRV_TCONST"], 0.05)
        rate = (roll_deg - np.degrees(s.phi)) / tau
        if p["RLL2SRV_RMAX"]:
            rate = float(np.clip(rate, -p["RLL2SRV_RMAX"], p["RLL2SRV_RMAX"]))
        aileron = self.roll.step(rate, S, s.p, dt, s.eas2tas, underspeed=s.eas <= p["AIRSPEED_MIN"])
        demand = pitch_deg + p["PTCH_TRIM_DEG"]
        tau = max(p["PTCH2SRV_TCONST"], 0.05)
        rate = (demand - np.degrees(s.theta)) / tau + self._turn_pitch_rate(s)
        if p["PTCH2SRV_RMAX_DN"] and rate < -p["PTCH2SRV_RMAX_DN"]:
            rate = -p["PTCH2SRV_RMAX_DN"]
        elif p["PTCH2SRV_RMAX_UP"] and rate > p["PTCH2SRV_RMAX_UP"]:
            rate = p["PTCH2SRV_RMAX_UP"]
        elevator = self.pitch.step(
            rate, S, s.q, dt, s.eas2tas, underspeed=s.eas <= 0.5 * p["AIRSPEED_MIN"]
        )
        rudder = self._yaw_damper(s, S, dt) + aileron * p["KFF_RDDRMIX"]
        rudder += float(np.clip(rudder_stick, -1, 1)) * TRAVEL_DEG
        return Surfaces(
            aileron=aileron,
            elevator=elevator,
            rudder=float(np.clip(rudder, -TRAVEL_DEG, TRAVEL_DEG)),
            roll_demand_deg=float(roll_deg),
            pitch_demand_deg=float(demand),
        )

    def _turn_pitch_rate(self, s: Sensed) -> float:
        """The pitch rate a level turn at this bank needs (deg/s), PTCH2SRV_RLL of it."""
        p = self.params
        if abs(np.degrees(s.theta)) > 70.0:
            return 0.0
        phi = float(np.clip(s.phi, -np.radians(80), np.radians(80)))
        tas = max(s.eas * s.eas2tas, max(p["AIRSPEED_MIN"], 1.0))
        turn = abs(np.degrees(G / tas * np.tan(phi) * np.sin(phi)))
        return float(np.cos(s.theta) * turn * p["PTCH2SRV_RLL"])

    def _yaw_damper(self, s: Sensed, S: float, dt: float) -> float:
        """AP_YawController: the yaw rate less the turn's, high-passed, damped by YAW2SRV_DAMP
        with the integrator of YAW2SRV_INT on it and the sideslip's acceleration (deg)."""
        p = self.params
        damp, integral = p["YAW2SRV_DAMP"], p["YAW2SRV_INT"]
        as_min = max(p["AIRSPEED_MIN"], 1.0)
        phi = float(np.clip(s.phi, -np.radians(80), np.radians(80)))
        turn = G / max(s.eas, as_min) * np.sin(phi) * p["YAW2SRV_RLL"]
        rate_in = float(np.degrees(s.r - turn))
        self._yaw_out = YAW_HIGH_PASS * self._yaw_out + rate_in - self._yaw_in
        self._yaw_in = rate_in
        if damp > 0:
            delta = -integral * (p["YAW2SRV_SLIP"] * s.ay + self._yaw_out) * dt
            if s.eas > as_min:
                if self._yaw_last_out < -TRAVEL_DEG:
                    delta = max(delta, 0.0)
                elif self._yaw_last_out > TRAVEL_DEG:
                    delta = min(delta, 0.0)
                self._yaw_integrator += delta
        else:
            self._yaw_integrator = 0.0
        if damp < 1e-4:
            self._yaw_damp_last = damp
            return 0.0
        limit = p["YAW2SRV_IMAX"] * 0.01 / (damp * S * S)
        self._yaw_integrator = float(np.clip(self._yaw_integrator, -limit, limit))
        if damp > self._yaw_damp_last > 0:
            self._yaw_integrator *= self._yaw_damp_last / damp
        self._yaw_damp_last = damp
        out = damp * S * S * (self._yaw_integrator - self._yaw_out)
        self._yaw_last_out = float(out)
        return float(np.clip(out, -TRAVEL_DEG, TRAVEL_DEG))
