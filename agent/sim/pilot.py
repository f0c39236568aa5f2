"""A scripted safety pilot: holds the trimmed sticks, flips the excitation switch on a
schedule or on request, takes control back (switch low), and recovers a departure in a
stabilised mode (`departed`)."""

from __future__ import annotations

import math
from collections.abc import Mapping

CHANNELS = 18
LOW_US, HIGH_US, CENTRE_US = 1100, 1900, 1500
# A departure the safety pilot recovers from (`departed`): bank beyond DEPART_BANK_DEG (the
# agent's envelope in `sysid sim`, whose monitor ends a run there and hands back trimmed
# sticks, which do not stop a spiral: JSBSim's DHC-6 touched the ground 48 s into its build-up
# run, its T-37 115 s into its second), the pitch attitude more than DEPART_PITCH_DEG from
# the trim's, the airspeed outside DEPART_SPEED of the trim's, or less than DEPART_HEIGHT of
# the trim's height above the ground left (the T-37's shallow dive: pitch −5°, 12 % fast, the
# envelope's height limit of 3 s of airspeed deeper than the 1000 ft it flew at). Recovered
# (`recovered`): within RECOVERED_BANK_DEG of wings level and half the pitch and airspeed
# margins.
DEPART_BANK_DEG = 45.0
DEPART_PITCH_DEG = 20.0
DEPART_SPEED = (0.7, 1.25)
DEPART_HEIGHT = 0.5
RECOVERED_BANK_DEG = 15.0


class ScriptedPilot:
    """RC inputs of every channel at a given time (call with the clock's time)."""

    def __init__(self, sticks: Mapping[int, int], switch_channel: int):
        self._rc = [CENTRE_US] * CHANNELS
        for channel, pwm in sticks.items():
            self._rc[channel - 1] = int(pwm)
        self.switch_channel = switch_channel
        self._rc[switch_channel - 1] = LOW_US
        self._schedule: list[tuple[float, bool]] = []

    def __call__(self, now: float) -> list[int]:
        while self._schedule and self._schedule[0][0] <= now:
            _, high = self._schedule.pop(0)
            self.set_switch(high)
        return list(self._rc)

    def set_stick(self, channel: int, pwm: int) -> None:
        """Move one stick (RC channel 1…) to a PWM value; the switch channel is not a stick."""
        if channel == self.switch_channel:
            raise ValueError(f"channel {channel} is the excitation switch")
        self._rc[channel - 1] = int(pwm)

    def stick(self, channel: int) -> int:
        return self._rc[channel - 1]

    def set_switch(self, high: bool) -> None:
        """Flip the excitation switch now."""
        self._rc[self.switch_channel - 1] = HIGH_US if high else LOW_US

    def schedule(self, at: float, high: bool) -> None:
        """Flip the switch at a future time of the clock."""
        self._schedule.append((at, high))
        self._schedule.sort()

    def take_control(self) -> None:
        """Switch low: any excitation stops and the sticks are the pilot's again."""
        self._schedule.clear()
        self.set_switch(False)

    @property
    def switch_high(self) -> bool:
        return self._rc[self.switch_channel - 1] >= HIGH_US


def departed(state: Mapping[str, float], trim: Mapping[str, float]) -> str | None:
    """Why the aircraft (`state`, agent.sim.plant.Plant.state) has departed from the flight
    trimmed at `trim`, by the module's thresholds; None where it has not."""
    bank = math.degrees(abs(state["phi"]))
    if bank > DEPART_BANK_DEG:
        return f"bank {bank:.0f}°"
    pitch = math.degrees(state["theta"] - trim["theta"])
    if abs(pitch) > DEPART_PITCH_DEG:
        return f"pitch {pitch:+.0f}° from the trim's"
    ratio = state["Vt"] / trim["Vt"]
    if not DEPART_SPEED[0] <= ratio <= DEPART_SPEED[1]:
        return f"airspeed {ratio:.2f} × the trim's"
    if "agl" in trim and state["agl"] < DEPART_HEIGHT * trim["agl"]:
        return f"{state['agl']:.0f} m above the ground, of {trim['agl']:.0f}"
    return None


def recovered(state: Mapping[str, float], trim: Mapping[str, float]) -> bool:
    """Back in flight near the trim after a departure (module constants)."""
    low, high = DEPART_SPEED
    return (
        math.degrees(abs(state["phi"])) < RECOVERED_BANK_DEG
        and abs(math.degrees(state["theta"] - trim["theta"])) < DEPART_PITCH_DEG / 2
        and 1 - (1 - low) / 2 <= state["Vt"] / trim["Vt"] <= 1 + (high - 1) / 2
    )
