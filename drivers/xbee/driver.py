"""The radio transport, the same on the aircraft and on the ground: digi-xbee's
`DigiMeshDevice`, bridged into asyncio through one seam.

Why digi-xbee and not our own frame codec on the port: it is the vendor's maintained library
(API modes, AT parameters, the module zoo), and the design card names it. Its pitfalls
(docs/protocols.md, *What digi-xbee 1.5.0 does*) are handled here: `open()` and AT reads
block, so they run on a worker thread; the blocking `send_data` can stall 4 s, so frames go out
with `send_packet(sync=False)` (on a writer thread: the UART write itself blocks) and our own
frame ids, and each 0x8B Transmit Status resolves the matching send; callbacks arrive on
digi-xbee's thread pool in any order, so they cross into the loop in exactly one place
(`PacketSeam`, `loop.call_soon_threadsafe`; docs/contributing.md, *One seam per threaded
library*), with a bound on how many may wait (drops counted), and the link layer above
carries its own sequence numbers. That callback takes no lock and logs nothing: it appends to
a deque and counts in a plain attribute, and the loop does the rest.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from digi.xbee.devices import DigiMeshDevice
from digi.xbee.exception import XBeeException
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.packets.aft import ApiFrameType
from digi.xbee.packets.common import TransmitPacket

from drivers.values import Clock

log = logging.getLogger(__name__)

# Longest wait for a Transmit Status: the module retries for well under a second; beyond this
# the frame is counted as unconfirmed (the session layer retransmits anyway).
STATUS_TIMEOUT_S = 5.0
# Received frames allowed to wait for the loop; more are dropped and counted.
INBOX = 256
# Opening a module takes milliseconds, and a module that does not answer fails digi-xbee's
# own per-command timeout (4 s); this only ends an open that is wedged. It is generous: on a
# machine with both cores busy an open that answers took over 10 s (test_console.py's rig),
# and each failed open starts the next from the beginning.
OPEN_TIMEOUT_S = 30.0
# How often `watch` looks at the port, and the longest wait between attempts to reopen it.
WATCH_S = 1.0
REOPEN_MAX_S = 8.0
DELIVERY = {
    0x00: "ok",
    0x01: "MAC ACK failure",
    0x21: "network ACK failure",
    0x25: "route not found",
    0x74: "payload too large",
}


class RadioError(RuntimeError):
    """The radio cannot be opened or used."""


@dataclass(frozen=True)
class SendResult:
    status: int
    retries: int

    @property
    def ok(self) -> bool:
        return self.status == 0

    @property
    def reason(self) -> str:
        return DELIVERY.get(self.status, f"status 0x{self.status:02X}")


class PacketSeam:
    """digi-xbee's callback threads → the loop, in exactly one place: `callback` (what
    digi-xbee is given) appends the packet to a deque and schedules one `deliver(packet)` on
    the loop. It takes no lock and logs nothing (docs/hardening.md, *Reliability*): deque
    append, len and popleft are atomic, and past `bound` packets waiting a packet is dropped
    and counted in a plain attribute (`dropped`) that the loop publishes. With several callback
    threads the bound may be passed by as many, and two drops at the same instant may count
    one."""

    def __init__(
        self, loop: asyncio.AbstractEventLoop, deliver: Callable[[object], None], bound: int = INBOX
    ):
        self.loop, self._deliver, self._bound = loop, deliver, bound
        self._inbox: deque = deque()
        self.dropped = 0

    def callback(self, packet) -> None:  # on a digi-xbee callback thread
        if len(self._inbox) >= self._bound:
            self.dropped += 1
            return
        self._inbox.append(packet)
        with contextlib.suppress(RuntimeError):  # a closed loop: shutting down
            self.loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        try:
            packet = self._inbox.popleft()
        except IndexError:
            return
        self._deliver(packet)


class XBeeRadio:
    """One XBee module on a serial port."""

    def __init__(
        self,
        port: str,
        baud: int,
        clock: Clock,
        on_frame: Callable[[bytes, bytes, float], None],
        on_open: Callable[[XBeeRadio], None] | None = None,
        require_encryption: bool = False,
    ):
        self.port, self.baud, self._clock, self._on_frame = port, baud, clock, on_frame
        self.require_encryption = require_encryption
        self.encrypted: bool | None = None
        """The module's AES encryption (AT EE) as read at the last open; None: not known."""
        self._on_open = on_open
        self._device = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="xbee-open")
        # Set when the open under way is given up (its timeout, or close()): the opening thread
        # then closes what it opened itself, even after the loop is gone.
        self._abandoned = threading.Event()
        self._writer = ThreadPoolExecutor(1, thread_name_prefix="xbee-tx")
        self._pending: dict[int, asyncio.Future] = {}
        self._next_id = 0
        # Where digi-xbee's threads hand frames to the loop (made at the first open).
        self._seam: PacketSeam | None = None
        self.max_payload = 0
        self.address = b""
        self.counters: Counter[str] = Counter()

    async def open(self) -> None:
        """Open the module (digi-xbee reads its parameters), read NP and our address."""
        self._loop = loop = asyncio.get_running_loop()
        self._abandoned = abandoned = threading.Event()
        opening = loop.run_in_executor(self._executor, self._open_blocking, abandoned)
        try:
            async with asyncio.timeout(OPEN_TIMEOUT_S):
                device = await asyncio.shield(opening)
        except TimeoutError as exc:
            # The blocking open goes on in its thread; should it still succeed, that device is
            # closed, never left reading the port beside the next attempt's (two readers on one
            # port split its frames between them): by the thread itself, or, if it had already
            # looked, here once it is done.
            abandoned.set()
            opening.add_done_callback(self._close_late)
            raise RadioError(
                f"{self.port}: the XBee did not answer in {OPEN_TIMEOUT_S:g} s"
            ) from exc
        except asyncio.CancelledError:  # the caller gone (shutdown): the same, no error of ours
            abandoned.set()
            opening.add_done_callback(self._close_late)
            raise
        if self._seam is None or self._seam.loop is not loop:
            self._seam = PacketSeam(loop, self._dispatch)
        device.add_packet_received_callback(self._seam.callback)
        self._device = device
        if self.encrypted is False:
            self.counters["unencrypted_opens"] += 1
            log.warning(
                "%s: the XBee's AES encryption is off (EE = 0): any node on the network can "
                "change its settings by Remote AT commands; set EE = 1 and the same KY on both "
                "modules (or [link] require_encryption to refuse such a module)",
                self.port,
            )
        if self._on_open is not None:
            self._on_open(self)

    def _close_late(self, opening: asyncio.Future) -> None:
        if opening.cancelled() or opening.exception() is not None:
            return
        self.counters["late_opens_closed"] += 1
        try:
            self._loop.run_in_executor(self._executor, opening.result().close)
        except RuntimeError:  # the pool already shut down (close() ran): off the loop still
            threading.Thread(
                target=_close_quietly, args=(opening.result(),), name="xbee-close", daemon=True
            ).start()

    def _open_blocking(self, abandoned: threading.Event):
        device = DigiMeshDevice(self.port, self.baud)
        try:
            device.open()
            max_payload = int.from_bytes(device.get_parameter("NP"), "big")
            address = bytes(device.get_64bit_addr().address)
            try:
                encrypted: bool | None = device.get_parameter("EE") == b"\x01"
            except XBeeException:  # a module without EE: not known
                encrypted = None
        except (XBeeException, OSError) as exc:
            with contextlib.suppress(Exception):  # closing a half-open device may fail too
                device.close()
            raise RadioError(f"{self.port}: cannot open the XBee: {exc}") from exc
        if abandoned.is_set():  # given up meanwhile: never leave its reader on the port
            with contextlib.suppress(Exception):
                device.close()
            raise RadioError(f"{self.port}: the open was given up")
        if encrypted is not True and self.require_encryption:  # fail closed: unknown is off
            with contextlib.suppress(Exception):
                device.close()
            state = "is off (EE = 0)" if encrypted is False else "cannot be read (no answer to EE)"
            raise RadioError(
                f"{self.port}: the XBee's AES encryption {state} and [link] "
                "require_encryption is set: use a module with AES encryption, EE = 1 and KY"
            )
        self.max_payload, self.address, self.encrypted = max_payload, address, encrypted
        return device

    @property
    def is_open(self) -> bool:
        """A module is open here (it may since have been lost: `healthy` looks)."""
        return self._device is not None

    def healthy(self) -> bool:
        """The module's port is open, digi-xbee's reader is serving it, and the device behind
        the port's path is still the one we opened. The reader thread ends, and closes the
        port, on any exception other than InvalidPacketException while it builds a frame:
        fuzzing found frames with a good checksum that make its factory raise IndexError
        (fuzz/, target digi-xbee), and a corrupted UART byte passes an 8-bit checksum one time
        in 256. On an unplugged USB radio it does not end: it spins on "device reports
        readiness to read but returned no data", so the path is checked too."""
        device = self._device
        if device is None:
            return False
        try:
            if not device.comm_iface.is_interface_open:
                return False
            opened = os.fstat(device.serial_port.fileno()).st_rdev
            return os.stat(self.port).st_rdev == opened
        except (OSError, AttributeError, ValueError):  # the path gone, a half-torn-down device
            return False

    async def watch(self) -> None:
        """Open the module if it is not open yet, then reopen it whenever its port is lost,
        with backoff, until cancelled. Each failed open, loss and reopen is counted and
        logged; frames waiting for a status on the lost port time out as unconfirmed (the
        session retransmits). An agent starts flying with its radio closed this way: a module
        that does not answer at power-up costs the link, never the recording."""
        delay = WATCH_S
        while True:
            if self._device is not None:
                await asyncio.sleep(WATCH_S)
                if self.healthy():
                    continue
                self.counters["port_lost"] += 1
                log.warning("%s: the XBee's port was lost; reopening", self.port)
                old, self._device = self._device, None
                if old is not None:
                    with contextlib.suppress(Exception):
                        await self._loop.run_in_executor(self._executor, old.close)
            reopening = self.counters["port_lost"] > 0
            while self._device is None:
                try:
                    await self.open()
                except RadioError as exc:
                    self.counters["reopen_failures" if reopening else "open_failures"] += 1
                    log.warning("%s; retrying in %.0f s", exc, delay)
                    await asyncio.sleep(delay)
                    delay = min(2 * delay, REOPEN_MAX_S)
            delay = WATCH_S
            if reopening:
                self.counters["reopened"] += 1
                log.warning("%s: the XBee is open again", self.port)
            else:
                log.info("%s: the XBee is open", self.port)

    async def rssi(self) -> int | None:
        """Signal strength of the last frame received (DB, dBm); None if it cannot be read."""
        device = self._device
        if device is None or self._loop is None:
            return None
        try:
            value = await self._loop.run_in_executor(self._executor, device.get_parameter, "DB")
        except (XBeeException, OSError, ValueError):
            self.counters["rssi_errors"] += 1
            return None
        return -int.from_bytes(value, "big") if value else None

    async def close(self) -> None:
        self._abandoned.set()  # an open still under way closes its device itself
        device, self._device = self._device, None
        if device is not None and self._loop is not None:
            await self._loop.run_in_executor(self._executor, device.close)
        for future in self._pending.values():
            future.cancel()
        # The threads' queues drained first, awaited (an open may still be in digi-xbee's
        # timeouts): the shutdowns then join idle threads and never hold the loop.
        if self._loop is not None:
            for pool in (self._writer, self._executor):
                with contextlib.suppress(RuntimeError):  # already shut down
                    await self._loop.run_in_executor(pool, _nothing)
        self._writer.shutdown(wait=True)
        self._executor.shutdown(wait=True)

    # -- on the loop: what digi-xbee's threads handed over (PacketSeam) --------------------

    def _dispatch(self, packet) -> None:
        if self._seam is not None and self._seam.dropped:
            self.counters["inbox_dropped"] = self._seam.dropped
        kind = packet.get_frame_type()
        if kind == ApiFrameType.TRANSMIT_STATUS:
            future = self._pending.pop(packet.frame_id, None)
            if future is not None and not future.done():
                future.set_result(
                    SendResult(packet.transmit_status.code, packet.transmit_retry_count)
                )
        elif kind == ApiFrameType.RECEIVE_PACKET:
            self.counters["received"] += 1
            source = bytes(packet.x64bit_source_addr.address)
            self._on_frame(source, bytes(packet.rf_data), self._clock.now())

    # -- sending ----------------------------------------------------------------------------

    async def send(self, destination: bytes, payload: bytes) -> SendResult:
        """Transmit one frame and wait for its Transmit Status (or STATUS_TIMEOUT_S)."""

        device = self._device
        if device is None:
            raise RadioError("the XBee is not open")
        if len(payload) > self.max_payload:
            self.counters["too_large"] += 1
            return SendResult(0x74, 0)
        frame_id = self._frame_id()
        future = self._loop.create_future()
        self._pending[frame_id] = future
        packet = TransmitPacket(
            frame_id,
            XBee64BitAddress(destination),
            XBee16BitAddress.UNKNOWN_ADDRESS,
            0,
            0,
            payload,
            op_mode=device.operating_mode,
        )
        try:
            # The write blocks until the UART has taken the frame (23 ms for 260 bytes at
            # 115200 baud): never on the loop.
            await self._loop.run_in_executor(self._writer, device.send_packet, packet, False)
            self.counters["sent"] += 1
            async with asyncio.timeout(STATUS_TIMEOUT_S):  # not wait_for: see session.run
                result = await future
        except TimeoutError:
            self.counters["status_timeouts"] += 1
            return SendResult(0xFF, 0)
        except Exception as exc:  # digi-xbee raises XBeeException and serial errors alike
            self.counters["send_errors"] += 1
            raise RadioError(f"cannot send: {exc}") from exc
        finally:
            self._pending.pop(frame_id, None)
        self.counters["ok" if result.ok else f"failed_{result.status:02x}"] += 1
        return result

    def _frame_id(self) -> int:
        """1 … 255, skipping ids still waiting for a status (0 would ask for none)."""
        for _ in range(255):
            self._next_id = self._next_id % 255 + 1
            if self._next_id not in self._pending:
                return self._next_id
        raise RadioError("255 frames are waiting for a transmit status")


def _close_quietly(device) -> None:
    with contextlib.suppress(Exception):  # closing what was given up: nothing to report
        device.close()


def _nothing() -> None:
    """A no-op for an executor: awaited, it returns once the work queued before it is done."""
