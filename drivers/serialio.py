"""The serial transport every sensor shares: pyserial-asyncio, with reconnection as a small
state machine (docs/contributing.md, *Reconnecting*) and a silence watchdog.

    waiting ──open ok──▶ open ──port error / EOF──▶ waiting (after backoff)
       ▲ └─open fails─┐   └──no byte for silence_s──▶ waiting (after backoff)
       └── backoff ◀──┘

The backoff starts at `initial` and doubles up to `maximum`; a session that delivered bytes
resets it. Bytes go to `on_data(chunk, arrival_time)` as they arrive.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass

import serial
import serial_asyncio

from drivers.values import Clock

log = logging.getLogger(__name__)

# Opening a local serial device takes milliseconds; a hung USB adapter must not stall us.
OPEN_TIMEOUT_S = 2.0


@dataclass
class LinkStats:
    """What the transport has seen; read by health reports."""

    state: str = "waiting"
    opens: int = 0
    open_failures: int = 0
    disconnects: int = 0
    silences: int = 0
    bytes_received: int = 0
    last_error: str = ""


class Backoff:
    """Capped exponential backoff: initial, ×2 per failure, at most maximum."""

    def __init__(self, initial: float, maximum: float):
        self.initial, self.maximum = initial, maximum
        self._next = initial

    def next(self) -> float:
        delay = self._next
        self._next = min(self._next * 2, self.maximum)
        return delay

    def reset(self) -> None:
        self._next = self.initial


class _Protocol(asyncio.Protocol):
    def __init__(self, link: SerialLink):
        self._link = link
        self.lost: asyncio.Future[Exception | None] = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self._link._received(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.lost.done():
            self.lost.set_result(exc)


class SerialLink:
    """Keeps one serial port open and feeds its bytes to `on_data`."""

    def __init__(
        self,
        name: str,
        port: str,
        baud: int,
        clock: Clock,
        on_data: Callable[[bytes, float], None],
        *,
        silence_s: float,
        backoff: Backoff,
        on_open: Callable[[asyncio.Transport], None] | None = None,
    ):
        self.name, self.port, self.baud = name, port, baud
        self._clock, self._on_data, self._on_open = clock, on_data, on_open
        self._silence_s, self._backoff = silence_s, backoff
        self.stats = LinkStats()
        self._last_byte = 0.0

    def _received(self, data: bytes) -> None:
        now = self._clock.now()
        self._last_byte = now
        self.stats.bytes_received += len(data)
        self._on_data(data, now)

    async def run(self) -> None:
        """Serve the port until cancelled."""
        while True:
            delivered = await self._session()
            if delivered:
                self._backoff.reset()
            self.stats.state = "waiting"
            await asyncio.sleep(self._backoff.next())

    async def _session(self) -> bool:
        """One open port, until it fails or falls silent; True if bytes arrived."""
        loop = asyncio.get_running_loop()
        before = self.stats.bytes_received
        try:
            async with asyncio.timeout(OPEN_TIMEOUT_S):  # not wait_for: see link.session
                transport, protocol = await serial_asyncio.create_serial_connection(
                    loop, lambda: _Protocol(self), self.port, baudrate=self.baud
                )
        except (OSError, serial.SerialException, TimeoutError) as exc:
            self.stats.open_failures += 1
            self._note(f"cannot open {self.port}: {exc}", first=self.stats.open_failures == 1)
            return False
        self.stats.opens += 1
        self.stats.state = "open"
        self._last_byte = self._clock.now()
        log.info("%s: %s open", self.name, self.port)
        try:
            if self._on_open is not None:
                self._on_open(transport)
            await self._watch(protocol)
        finally:
            transport.close()
        return self.stats.bytes_received > before

    async def _watch(self, protocol: _Protocol) -> None:
        while True:
            done, _ = await asyncio.wait({protocol.lost}, timeout=self._silence_s / 4)
            if done:
                self.stats.disconnects += 1
                self._note(f"{self.port} lost: {protocol.lost.result() or 'end of file'}")
                return
            if self._clock.now() - self._last_byte > self._silence_s:
                self.stats.silences += 1
                self._note(f"{self.port} silent for {self._silence_s:g} s: reopening")
                return

    def _note(self, message: str, first: bool = True) -> None:
        self.stats.last_error = message
        if first:
            log.warning("%s: %s", self.name, message)
