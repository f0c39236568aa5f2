"""The recorder: fixed-rate frames over the configured channels, a ring buffer a time window
can be copied from, excitation-window marks, and the flight and excitation logs.

Drivers push samples (agent-clock time, values by channel) as they arrive. At every frame time
T (default every 10 ms, assembled `delay_s` later so the samples around T are in), each channel
is sampled by linear interpolation between the samples around T or by holding the latest one
(flags, counters), and the age of its newest sample at T is recorded beside it; a channel whose
newest sample is older than `max_age_s` is recorded empty (NaN) — a gap is visible, never
papered over.

Samples can come later than `delay_s`: a loop held up by a busy CPU, or a device's backlog read
in pieces after it (pyserial-asyncio reads a port's buffer a chunk per loop turn, and the readers
run after the recorder's own wake-up). While a live channel's next sample is overdue, the frames
after its newest sample wait for it, up to `hold_s` after their time, so late data are recorded,
not lost; a channel silent for longer than that (unplugged) holds nothing back.

Nothing here blocks: histories and the ring are fixed-size, and rows go to the log writer
thread through its bounded queue (drops counted).
"""

from __future__ import annotations

import logging
import math
from bisect import bisect_right
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from agent.channels import SENSOR_CHANNELS
from agent.clock import Clock
from agent.config import Recorder as RecorderConfig
from drivers.sensor import Sample
from drivers.values import Window

log = logging.getLogger(__name__)

# Samples kept per channel: the frames they serve are at most `hold_s` old (≤ 5 s), and a
# channel samples at up to 1000 Hz (a VN-200's binary output); older ones are dropped by time.
HISTORY = 6000
# Past the newest sample's time, its channel's next is due within this many of its intervals
# (the devices' clocks are smooth; a dropped frame doubles one interval).
DUE_INTERVALS = 2.5
# The intervals a channel's sample interval is averaged over.
INTERVALS = 10
# Excitation windows remembered.
MARKS = 256


@dataclass(frozen=True)
class Frames:
    """A copy of recorded frames: times, and values and ages by channel."""

    time: np.ndarray
    values: dict[str, np.ndarray]
    ages: dict[str, np.ndarray]


class _History:
    """Recent (time, value) samples of one channel, oldest first."""

    __slots__ = ("times", "values")

    def __init__(self) -> None:
        self.times: deque[float] = deque(maxlen=HISTORY)
        self.values: deque[float] = deque(maxlen=HISTORY)

    def due(self) -> float:
        """The time by which this channel's next sample is due (inf while it has fewer than
        two: nothing to expect yet)."""
        times = self.times
        n = min(len(times) - 1, INTERVALS)
        if n < 1:
            return math.inf
        return times[-1] + DUE_INTERVALS * (times[-1] - times[-1 - n]) / n

    def forget_before(self, t: float) -> None:
        """Drop samples older than t, keeping the newest before it (a hold or an interpolation
        at t still needs it) and the last INTERVALS + 1 (the next sample's due time)."""
        times, values = self.times, self.values
        while len(times) > INTERVALS + 1 and times[1] <= t:
            times.popleft()
            values.popleft()

    def sample(self, t: float, linear: bool, max_age: float) -> tuple[float, float]:
        """(value, age) at t."""
        times = self.times
        j = bisect_right(times, t) - 1
        if j < 0:
            return math.nan, math.nan
        t0, v0 = times[j], self.values[j]
        age = t - t0
        if age > max_age:
            return math.nan, age
        if linear and j + 1 < len(times) and times[j + 1] - t0 <= max_age:
            t1, v1 = times[j + 1], self.values[j + 1]
            return v0 + (v1 - v0) * (t - t0) / (t1 - t0), age
        return v0, age


class Ring:
    """The newest `capacity` rows of a fixed width, as one preallocated array. Rows are appended
    in increasing time (column 0), so a time window is found by binary search and only its rows
    are copied (copying the whole ring, 24 MB at the default ten minutes, stalled the loop)."""

    def __init__(self, capacity: int, width: int):
        self._data = np.full((capacity, width), np.nan)
        self._time = np.full(capacity, np.nan)  # column 0, contiguous for searchsorted
        self._next = 0
        self.count = 0

    def append(self, row: np.ndarray) -> None:
        self._data[self._next] = row
        self._time[self._next] = row[0]
        self._next = (self._next + 1) % len(self._data)
        self.count = min(self.count + 1, len(self._data))

    @property
    def newest(self) -> float | None:
        """Column 0 of the newest row (None while empty)."""
        return None if self.count == 0 else float(self._time[self._next - 1])

    def _segments(self) -> list[slice]:
        """The stored rows as slices of the array, oldest first."""
        if self.count < len(self._data):
            return [slice(0, self.count)]
        return [slice(self._next, len(self._data)), slice(0, self._next)]

    def ordered(self) -> np.ndarray:
        """A copy of the stored rows, oldest first."""
        return np.concatenate([self._data[s] for s in self._segments()])

    def between(self, t0: float, t1: float) -> np.ndarray:
        """A copy of the rows whose time (column 0) lies in [t0, t1]."""
        parts = []
        for part in self._segments():
            times = self._time[part]
            lo = int(np.searchsorted(times, t0, side="left"))
            hi = int(np.searchsorted(times, t1, side="right"))
            if hi > lo:
                parts.append(self._data[part][lo:hi])
        if not parts:
            return np.empty((0, self._data.shape[1]))
        return np.concatenate(parts) if len(parts) > 1 else parts[0].copy()


class Recorder:
    """See the module docstring. `sink(row)` receives every frame (the flight log)."""

    def __init__(
        self,
        config: RecorderConfig,
        clock: Clock,
        *,
        channels: Sequence[str] | None = None,
        sink: Callable[[np.ndarray], None] | None = None,
        on_excitation: Callable[[object, np.ndarray], None] | None = None,
    ):
        self._config, self._clock = config, clock
        self.sink = sink
        """Receives every frame (the flight log); may be set after construction."""
        self._on_excitation = on_excitation
        self._pending: deque = deque(maxlen=MARKS)
        self.channels = list(channels or config.channels or SENSOR_CHANNELS)
        self._linear = [
            SENSOR_CHANNELS.get(c, ("", "linear"))[1] == "linear" for c in self.channels
        ]
        self._histories = {c: _History() for c in self.channels}
        self._dt = 1.0 / config.rate_hz
        self.ring = Ring(round(config.capacity_s * config.rate_hz), 1 + 2 * len(self.channels))
        self.marks: deque = deque(maxlen=MARKS)
        self.counters: Counter[str] = Counter()
        self._waited = -1  # the last frame that waited for a late sample

    @property
    def columns(self) -> list[str]:
        """Column names of a row: time, the channels, then each channel's age."""
        return ["time", *self.channels, *(f"{c}_age" for c in self.channels)]

    def push(self, sample: Sample) -> None:
        """A sample from a driver (called on the event loop; O(channels in the sample))."""
        late = False
        for name, value in sample.values.items():
            history = self._histories.get(name)
            if history is None:
                continue
            if history.times and sample.time <= history.times[-1]:
                late = True  # a duplicate, or stamped before one already held: keep order
                continue
            history.times.append(sample.time)
            history.values.append(value)
        if late:
            # Once per sample, whatever its channel count: a device's clock estimate settling
            # (its first samples arrive late, so are stamped late) sends a few back in time.
            self.counters["late_samples"] += 1

    def mark(self, event: object) -> None:
        """A scheduler event; a Window (plan id, axes, start, end, outcome) is kept, and its
        input/output log goes to `on_excitation` once the margin after it is recorded."""
        if not isinstance(event, Window):
            return
        window = event
        self.marks.append(window)
        self._pending.append(window)

    @property
    def waiting(self) -> Window | None:
        """The window whose margin is being recorded (its log and identification follow)."""
        return self._pending[0] if self._pending else None

    def _flush_excitations(self, latest: float) -> None:
        margin = self._config.excitation_margin_s
        while self._pending and self._pending[0].end + margin <= latest:
            window = self._pending.popleft()
            if self._on_excitation is not None:
                rows = self.ring.between(window.start - margin, window.end + margin)
                self._on_excitation(window, rows)

    def frame(self, t: float) -> np.ndarray:
        """The row for frame time t."""
        n = len(self.channels)
        row = np.empty(1 + 2 * n)
        row[0] = t
        max_age = self._config.max_age_s
        for k, (name, linear) in enumerate(zip(self.channels, self._linear, strict=True)):
            row[1 + k], row[1 + n + k] = self._histories[name].sample(t, linear, max_age)
        return row

    @property
    def newest(self) -> float | None:
        """The time of the newest frame in the ring (None while it is empty)."""
        return self.ring.newest

    def _ready_until(self, now: float) -> float:
        """Frames up to this time have every live channel's samples in: the newest sample's
        time of each channel whose next sample was due by `now` and has not come, over those
        heard from within `hold_s` (one silent for longer is unplugged or dead: its frames are
        recorded empty). A frame after it would hold that channel's newest sample in place of
        the late ones."""
        hold = self._config.hold_s
        ready = math.inf
        for history in self._histories.values():
            times = history.times
            if times and now - times[-1] < hold and history.due() < now:
                ready = min(ready, times[-1])
        return ready

    async def run(self) -> None:
        """Assemble a frame every 1/rate_hz s, `delay_s` after its time (or once its late
        samples are in, at most `hold_s` after it), until cancelled."""
        delay, hold, dt = self._config.delay_s, self._config.hold_s, self._dt
        start = self._clock.now()
        i = 0
        wake = start + delay
        while True:
            await self._clock.sleep_until(wake)
            now = self._clock.now()
            due = math.floor((now - delay - start) / dt + 1e-9)
            ready = self._ready_until(now)
            # Late frames are still assembled (the histories hold what they need): none is lost.
            assembled = 0
            while i <= due:
                t = start + i * dt
                if t > ready and now - t < hold:
                    if self._waited != i:  # a live channel's sample is late: wait for it
                        self._waited = i
                        self.counters["waited_frames"] += 1
                    break
                row = self.frame(t)
                self.ring.append(row)
                self.counters["frames"] += 1
                if self.sink is not None:
                    self.sink(row)
                assembled += 1
                i += 1
            if assembled > 1:
                self.counters["catch_up_frames"] += assembled - 1
            if assembled:
                last = start + (i - 1) * dt
                for history in self._histories.values():
                    history.forget_before(last)
                self._flush_excitations(last)
            # The next frame's time, or a frame's period from now while one waits.
            wake = start + i * dt + delay if i > due else now + dt

    def window(self, t0: float, t1: float) -> Frames:
        """A copy of the frames with time in [t0, t1]."""
        return self.frames(self.ring.between(t0, t1))

    def frames(self, rows: np.ndarray) -> Frames:
        """Rows of the ring (`Ring.between`, a logged window) by channel: the one place that
        knows the row layout [time, values…, ages…]. Views into `rows`, not copies."""
        n = len(self.channels)
        return Frames(
            time=rows[:, 0],
            values={c: rows[:, 1 + k] for k, c in enumerate(self.channels)},
            ages={c: rows[:, 1 + n + k] for k, c in enumerate(self.channels)},
        )
