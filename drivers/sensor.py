"""One sensor = serial link → stream decoder → conversion → time alignment → samples.

Each device's driver.py supplies its codec and a `convert(message) -> Reading | None`; this
module does the rest the same way for all of them and keeps the health every other part of
the agent reads (rate, checksum errors, resyncs, bytes skipped, gaps, age of the last sample).
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.codec import Codec, StreamDecoder
from drivers.config import SerialPort
from drivers.serialio import Backoff, SerialLink
from drivers.timing import DeviceClock
from drivers.values import Clock

log = logging.getLogger(__name__)

# A gap is a pause longer than this many nominal sample periods.
GAP_PERIODS = 1.5
# Gaps remembered for reports (the count keeps growing).
GAP_LOG = 100


@dataclass(frozen=True)
class Reading:
    """A converted message: the device's own time stamp (s, None if it has none) and values
    by canonical channel name in SI units."""

    device_time: float | None
    values: dict[str, float]


@dataclass(frozen=True)
class Sample:
    """A reading placed on the agent clock."""

    source: str
    time: float
    values: dict[str, float]


@dataclass(frozen=True)
class Health:
    """A sensor's health at one moment."""

    name: str
    state: str
    rate_hz: float
    """Samples over the last second by their own (device-clock) times: the sensor's rate,
    whatever bursts the serial path delivers them in."""
    # The codec's counters (CodecStats), each under its own name.
    frames: int
    crc_errors: int
    resyncs: int
    bytes_skipped: int
    rejected: int
    gaps: int
    last_sample_age: float | None
    opens: int
    disconnects: int
    silences: int
    clock_resets: int
    gap_log: tuple[tuple[float, float], ...] = field(default=(), repr=False)


class SensorDriver:
    """A sensor on a serial port: run() serves it until cancelled."""

    def __init__(
        self,
        name: str,
        port: SerialPort,
        backoff: Backoff,
        codec: Codec,
        convert: Callable[[object], Reading | None],
        publish: Callable[[Sample], None],
        clock: Clock,
        *,
        on_open: Callable[[asyncio.Transport], None] | None = None,
        on_reconnect: Callable[[], None] | None = None,
    ):
        self.name = name
        self._period = 1.0 / port.rate_hz
        self._decoder = StreamDecoder(codec)
        self._convert, self._publish, self._clock = convert, publish, clock
        self._device_clock = DeviceClock()
        self._on_open, self._on_reconnect = on_open, on_reconnect
        self.link = SerialLink(
            name,
            port.port,
            port.baud,
            clock,
            self._on_data,
            silence_s=port.silence_s,
            backoff=backoff,
            on_open=self._opened,
        )
        self._last_time: float | None = None
        self._recent: deque[float] = deque(maxlen=int(4 * port.rate_hz) + 8)
        self._gaps = 0
        self._gap_log: deque[tuple[float, float]] = deque(maxlen=GAP_LOG)

    async def run(self) -> None:
        await self.link.run()

    def _opened(self, transport: asyncio.Transport) -> None:
        # A reopened port may be a restarted device: its clock and counters start afresh.
        if self.link.stats.opens > 1:
            self._device_clock.reset()
            if self._on_reconnect is not None:
                self._on_reconnect()
        if self._on_open is not None:
            self._on_open(transport)

    def _on_data(self, chunk: bytes, arrival: float) -> None:
        for message in self._decoder.feed(chunk):
            reading = self._convert(message)
            if reading is None:
                continue
            if reading.device_time is None:
                time = arrival
            else:
                time = self._device_clock.local(reading.device_time, arrival)
            if self._last_time is not None and time - self._last_time > GAP_PERIODS * self._period:
                self._gaps += 1
                self._gap_log.append((self._last_time, time))
                log.warning("%s: %.3f s gap in samples", self.name, time - self._last_time)
            self._last_time = time
            self._recent.append(time)
            self._publish(Sample(self.name, time, reading.values))

    def health(self) -> Health:
        now = self._clock.now()
        window = [t for t in self._recent if now - t <= 1.0]
        link = self.link.stats
        return Health(
            name=self.name,
            state=link.state,
            rate_hz=float(len(window)),
            **self._decoder.stats.as_dict(),
            gaps=self._gaps,
            last_sample_age=None if self._last_time is None else now - self._last_time,
            opens=link.opens,
            disconnects=link.disconnects,
            silences=link.silences,
            clock_resets=self._device_clock.resets,
            gap_log=tuple(self._gap_log),
        )
