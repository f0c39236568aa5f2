"""Two (or more) emulated XBee-PRO 900HP modules on pseudo-terminals, joined by an RF channel.

Each module answers, on its pty, what digi-xbee asks when it opens a DigiMesh device (AT AP,
HV, VR, SH, SL, NI, CE; SS answered "invalid command"; NP, the maximum payload) and then
carries 0x10 Transmit Requests to the addressed module as 0x90 Receive Packets, answering the
sender with a 0x8B Transmit Status. The channel model: a shared half-duplex channel at a data
rate, a latency, independent loss of each attempt with up to `retries` MAC retries (status
0x21 when all fail), a payload limit (0x74), and outages (0x25 route not found).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import Clock
from agent.sim.devices import PtyPort
from drivers.codec import StreamDecoder
from drivers.xbee import codec as api

HV_900HP = b"\x23\x01"
VR_DIGIMESH = b"\x80\x75"
# Per-frame radio overhead on air (preamble, MAC header, CRC), bytes.
AIR_OVERHEAD = 30


# Shaped like drivers/codec.py's CodecStats only: settings of the simulated air, not counters.
@dataclass
class RfChannel:
    """The air between the modules."""

    data_rate_bps: float = 200_000.0
    """900HP RF data rate: 200 kb/s (10 kb/s in its long-range setting)."""
    latency_s: float = 0.005
    loss: float = 0.0
    """Probability that one over-the-air attempt is lost."""
    retries: int = 3
    """MAC retries before the sender gets a network ACK failure."""
    payload_limit: int = 256
    """Largest RF payload (NP)."""
    outage: bool = False
    """True: nothing gets through (route not found)."""
    rssi_dbm: int = -62
    """Received signal strength of a frame that gets through (what DB reports)."""
    seed: int = 0
    busy_until: float = 0.0
    rng: random.Random = field(default_factory=random.Random)
    air_bytes: int = 0
    """Bytes put on the air, retries and overhead included."""
    heard: deque = field(default_factory=lambda: deque(maxlen=256))
    """(source, destination, payload) of frames delivered: what an eavesdropper records."""

    def __post_init__(self) -> None:
        self.rng.seed(self.seed)


class EmulatedXBee:
    """One module: its pty, its address, the channel it shares with its peers."""

    def __init__(
        self,
        name: str,
        address: bytes,
        directory: Path,
        channel: RfChannel,
        clock: Clock,
        *,
        escaped: bool = False,
    ):
        self.name, self.address, self.channel, self._clock = name, address, channel, clock
        self.port = PtyPort(Path(directory) / name)
        self.escaped = escaped
        self._codec = api.ApiCodec(escaped)
        self._decoder = StreamDecoder(self._codec)
        self.network: dict[bytes, EmulatedXBee] = {}
        self.counters: Counter[str] = Counter()
        self._tasks: set[asyncio.Task] = set()
        self.encryption: bool | None = False
        """The module's AES encryption (EE) as configured: off, as a module ships; None: a
        module without encryption, which answers EE as an invalid command."""

    @property
    def path(self) -> Path:
        return self.port.path

    def join(self, *others: EmulatedXBee) -> None:
        for module in (self, *others):
            self.network[module.address] = module

    async def run(self) -> None:
        self.plug()
        try:
            await asyncio.Event().wait()  # serve until cancelled
        finally:
            self.unplug()
            for task in self._tasks:
                task.cancel()

    def plug(self) -> None:
        """The module's USB cable plugged in (a new pty behind the same path)."""
        if self.port.plugged:
            return
        self.port.plug()
        self._decoder = StreamDecoder(self._codec)
        asyncio.get_running_loop().add_reader(self.port.master_fd, self._readable)

    def unplug(self) -> None:
        """The cable pulled: the host's port goes away mid-stream."""
        if not self.port.plugged:
            return
        asyncio.get_running_loop().remove_reader(self.port.master_fd)
        self.port.unplug()

    def emit(self, frame: api.ApiFrame) -> None:
        """Any API frame to the host, checksum correct (a frame corrupted on the UART that
        still passes the 8-bit checksum, or a firmware oddity)."""
        self._send(frame)

    def _readable(self) -> None:
        try:
            data = os.read(self.port.master_fd, 4096)
        except (BlockingIOError, OSError):
            return
        for frame in self._decoder.feed(data):
            self._handle(frame)

    def _send(self, frame: api.ApiFrame) -> None:
        self.port.write(self._codec.encode(frame))

    def _handle(self, frame: api.ApiFrame) -> None:
        if frame.kind in (api.AT_COMMAND, api.AT_COMMAND_QUEUED):
            self._at(frame.data[1], frame.data[2:4], frame.data[4:])
        elif frame.kind == api.TRANSMIT_REQUEST:
            frame_id, destination, payload = api.parse_transmit_request(frame)
            self.counters["tx_requests"] += 1
            task = asyncio.get_running_loop().create_task(
                self._transmit(frame_id, destination, payload), name=f"{self.name}-tx"
            )
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        else:
            self.counters["unsupported_frames"] += 1

    def _at(self, frame_id: int, command: bytes, value: bytes) -> None:
        answers = {
            b"AP": bytes([2 if self.escaped else 1]),
            b"HV": HV_900HP,
            b"VR": VR_DIGIMESH,
            b"SH": self.address[:4],
            b"SL": self.address[4:],
            b"NI": self.name.encode(),
            b"CE": b"\x00",
            b"NP": self.channel.payload_limit.to_bytes(2, "big"),
            b"MY": b"\xff\xfe",
            b"BR": b"\x01",
            b"DB": bytes([min(255, max(0, -self.channel.rssi_dbm))]),
            b"EE": bytes([1 if self.encryption else 0]),
        }
        if self.encryption is None:
            del answers[b"EE"]
        if value and command in answers:  # a write: accepted, value unchanged here
            self._send(api.at_response(frame_id, command, 0))
        elif command in answers:
            self._send(api.at_response(frame_id, command, 0, answers[command]))
        else:
            self._send(api.at_response(frame_id, command, 2))  # invalid command

    async def transmit_as(self, source: bytes, destination: bytes, payload: bytes) -> None:
        """A hostile transmitter on the channel that forges its MAC source address (an SDR,
        not an XBee): the frame reaches `destination` as if from `source`, through the same
        air time, loss and outages."""
        self.counters["forged_source"] += 1
        await self._transmit(0, destination, payload, source=source)

    async def _transmit(
        self, frame_id: int, destination: bytes, payload: bytes, source: bytes | None = None
    ) -> None:
        ch = self.channel
        if len(payload) > ch.payload_limit:
            self.counters["too_large"] += 1
            self._status(frame_id, 0x74, 0)
            return
        peer = self.network.get(destination)
        attempts, delivered = 0, False
        while attempts <= ch.retries and not delivered:
            attempts += 1
            now = self._clock.now()
            start = max(now, ch.busy_until)
            airtime = (len(payload) + AIR_OVERHEAD) * 8 / ch.data_rate_bps
            ch.busy_until = start + airtime
            ch.air_bytes += len(payload) + AIR_OVERHEAD
            await self._clock.sleep_until(start + airtime + ch.latency_s)
            if peer is None or ch.outage:
                break
            delivered = ch.rng.random() >= ch.loss
        if peer is None or ch.outage:
            self.counters["no_route"] += 1
            self._status(frame_id, 0x25, attempts - 1)
            return
        if not delivered:
            self.counters["lost"] += 1
            self._status(frame_id, 0x21, attempts - 1)
            return
        self.counters["delivered"] += 1
        ch.heard.append((source or self.address, destination, payload))
        peer._send(api.receive_packet(source or self.address, payload))
        self._status(frame_id, 0x00, attempts - 1)

    def _status(self, frame_id: int, status: int, retries: int) -> None:
        if frame_id:  # frame id 0: the sender asked for no status
            with contextlib.suppress(OSError):
                self._send(api.transmit_status(frame_id, status, retries))


def module_pair(
    directory: Path,
    clock,
    air: tuple[str, bytes],
    ground: tuple[str, bytes],
    channel: RfChannel | None = None,
) -> tuple[RfChannel, EmulatedXBee, EmulatedXBee]:
    """Two modules (name, address) on one channel, each the other's only neighbour."""
    channel = channel or RfChannel()
    a = EmulatedXBee(air[0], air[1], directory, channel, clock)
    g = EmulatedXBee(ground[0], ground[1], directory, channel, clock)
    a.join(g)
    g.join(a)
    return channel, a, g
