"""Device time → agent time, and counters that wrap.

Every sensor stamps its samples with its own clock (VN-200 time since start-up, the µADC's
sample counter, the Arduino's millis). Arrival times on the agent carry the serial and
event-loop latency, which is never negative and often jittery; the device clock is smooth
but offset and slowly drifting. So the offset is the minimum of (arrival − device time) over
a sliding window (the least-delayed sample is the best witness), and a sample's agent time is
its device time plus that offset. A device reset (its clock jumping back, or a sample that
would have arrived before it was taken) restarts the estimate; a late sample never moves it.
"""

from __future__ import annotations

from collections import deque

# Samples in the sliding minimum: 10 s at 100 Hz, so a 50 ppm crystal drifts 0.5 ms within it.
WINDOW = 1000
# A change of offset bigger than this is a device reset or a replug, not drift or latency.
RESET_S = 0.5


class DeviceClock:
    """Maps device time stamps to agent time by a sliding-minimum offset."""

    def __init__(self, window: int = WINDOW):
        self._window = window
        self._candidates: deque[tuple[int, float]] = deque()  # (index, offset), increasing
        self._index = 0
        self._last_device = 0.0
        self.resets = 0

    def local(self, device_time: float, arrival: float) -> float:
        """Agent time of a sample taken at `device_time`, received at `arrival`."""
        offset = arrival - device_time
        if self._candidates and (
            device_time < self._last_device or offset < self.offset - RESET_S
        ):  # the device clock went back, or jumped ahead: it restarted
            self.reset()
        self._last_device = device_time
        while self._candidates and self._candidates[-1][1] >= offset:
            self._candidates.pop()
        self._candidates.append((self._index, offset))
        while self._candidates[0][0] <= self._index - self._window:
            self._candidates.popleft()
        self._index += 1
        return device_time + self.offset

    @property
    def offset(self) -> float:
        return self._candidates[0][1]

    def reset(self) -> None:
        self._candidates.clear()
        self._last_device = 0.0
        self.resets += 1


class Unwrap:
    """Unwraps a counter that wraps modulo `modulus` into a monotonic count."""

    def __init__(self, modulus: int):
        self._modulus = modulus
        self._last: int | None = None
        self._base = 0

    def __call__(self, value: int) -> int:
        if self._last is not None and value < self._last - self._modulus // 2:
            self._base += self._modulus
        elif self._last is not None and value > self._last + self._modulus // 2:
            self._base -= self._modulus  # a late sample from before the wrap
        self._last = value
        return self._base + value

    def reset(self) -> None:
        self._last, self._base = None, 0
