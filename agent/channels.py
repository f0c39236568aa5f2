"""Canonical channel roles, their units, and the identification axis sets.

A *role* is what a channel means (sideslip, roll rate, aileron…); the column or signal that
carries it is named in config (`[identification.channels]`), so logs with other naming
conventions can be identified without renaming.
"""

from __future__ import annotations

from typing import Literal

AxisSet = Literal["lateral", "longitudinal", "full"]

INPUT_ROLES = ("throttle", "elevator", "aileron", "rudder")
# A measured engine speed or thrust: where a record has one, the whole-aircraft method takes it
# as the longitudinal axis's known input, acting at once, instead of the throttle's command
# through the engine's fitted lags (agent.ident.aircraft). Not flown by the agent.
POWER_ROLES = ("rpm", "thrust")
LONGITUDINAL_OUTPUTS = ("airspeed", "alpha", "q", "theta")
LATERAL_OUTPUTS = ("beta", "p", "r", "phi")
OUTPUT_ROLES = LONGITUDINAL_OUTPUTS + LATERAL_OUTPUTS
# The INS's heading and velocity over the ground: with the attitude they give the still-air
# V, α, β, so the whole-aircraft method measures the wind (agent.ident.aircraft.prepare).
NAVIGATION_ROLES = ("psi", "vn", "ve", "vd")

UNITS = {
    "throttle": "µs",
    "elevator": "deg",
    "aileron": "deg",
    "rudder": "deg",
    "rpm": "rpm",
    "thrust": "N",
    "airspeed": "m/s",
    "alpha": "rad",
    "q": "rad/s",
    "theta": "rad",
    "beta": "rad",
    "p": "rad/s",
    "r": "rad/s",
    "phi": "rad",
    "psi": "rad",
    "vn": "m/s",
    "ve": "m/s",
    "vd": "m/s",
}

# Axis set → (input roles, output roles), thesis eq. 4.6–4.7 and A.2–A.4.
AXIS_SETS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "lateral": (("aileron", "rudder"), LATERAL_OUTPUTS),
    "longitudinal": (("throttle", "elevator"), LONGITUDINAL_OUTPUTS),
    "full": (INPUT_ROLES, OUTPUT_ROLES),
}


# Every channel the sensors publish (name → unit, hold). "linear": interpolated between the
# samples around a frame time; "zoh": the latest sample held (flags, counters, status words).
SENSOR_CHANNELS: dict[str, tuple[str, str]] = {
    # VN-200
    "phi": ("rad", "linear"),
    "theta": ("rad", "linear"),
    "psi": ("rad", "linear"),
    "p": ("rad/s", "linear"),
    "q": ("rad/s", "linear"),
    "r": ("rad/s", "linear"),
    "ax": ("m/s^2", "linear"),
    "ay": ("m/s^2", "linear"),
    "az": ("m/s^2", "linear"),
    "lat": ("deg", "linear"),
    "lon": ("deg", "linear"),
    "alt_gps": ("m", "linear"),
    "vn": ("m/s", "linear"),
    "ve": ("m/s", "linear"),
    "vd": ("m/s", "linear"),
    "ins_status": ("bits", "zoh"),
    "utc": ("s", "linear"),
    "vn_time": ("s", "zoh"),
    # µADC
    "Vt": ("m/s", "linear"),
    "ias": ("m/s", "linear"),
    "alpha": ("rad", "linear"),
    "beta": ("rad", "linear"),
    "alpha_clipped": ("flag", "zoh"),
    "beta_clipped": ("flag", "zoh"),
    "alt_pressure": ("m", "linear"),
    "p_total": ("Pa", "linear"),
    "p_static": ("Pa", "linear"),
    "adc_sample": ("count", "zoh"),
    # surface box
    "aileron": ("deg", "linear"),
    "elevator": ("deg", "linear"),
    "rudder": ("deg", "linear"),
    "flap": ("deg", "linear"),
    "aileron_left": ("deg", "linear"),
    "aileron_right": ("deg", "linear"),
    "elevator_left": ("deg", "linear"),
    "elevator_right": ("deg", "linear"),
    "flap_left": ("deg", "linear"),
    "flap_right": ("deg", "linear"),
    "rpm": ("rpm", "linear"),
    "box_seq": ("count", "zoh"),
    # autopilot (SERVO_OUTPUT_RAW): the throttle command in µs, as the thesis's models take it
    "throttle": ("us", "zoh"),
}
