"""Canonical channel roles, their units, and the identification axis sets.

A *role* is what a channel means (sideslip, roll rate, aileron…); the column or signal that
carries it is named in config (`[identification.channels]`), so logs with other naming
conventions can be identified without renaming.
"""

from __future__ import annotations

from typing import Literal

AxisSet = Literal["lateral", "longitudinal", "full"]

INPUT_ROLES = ("throttle", "elevator", "aileron", "rudder")
LONGITUDINAL_OUTPUTS = ("airspeed", "alpha", "q", "theta")
LATERAL_OUTPUTS = ("beta", "p", "r", "phi")
OUTPUT_ROLES = LONGITUDINAL_OUTPUTS + LATERAL_OUTPUTS

UNITS = {
    "throttle": "µs",
    "elevator": "deg",
    "aileron": "deg",
    "rudder": "deg",
    "airspeed": "m/s",
    "alpha": "rad",
    "q": "rad/s",
    "theta": "rad",
    "beta": "rad",
    "p": "rad/s",
    "r": "rad/s",
    "phi": "rad",
}

# Axis set → (input roles, output roles), thesis eq. 4.6–4.7 and A.2–A.4.
AXIS_SETS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "lateral": (("aileron", "rudder"), LATERAL_OUTPUTS),
    "longitudinal": (("throttle", "elevator"), LONGITUDINAL_OUTPUTS),
    "full": (INPUT_ROLES, OUTPUT_ROLES),
}
