"""A scripted safety pilot: holds the trimmed sticks, flips the excitation switch on a
schedule or on request, and takes control back (switch low)."""

from __future__ import annotations

from collections.abc import Mapping

CHANNELS = 18
LOW_US, HIGH_US, CENTRE_US = 1100, 1900, 1500


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
