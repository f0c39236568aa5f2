"""The autopilot driver: ArduPlane through MAVSDK 4.1 (`mavsdk.asyncio` and its
`mavlink_direct` plugin), and the scheduler's surface sink (RC_CHANNELS_OVERRIDE).

MAVSDK delivers messages on its own threads. They cross into the event loop in exactly one
place (`MessageSeam`; docs/contributing.md, *One seam per threaded library*): the callback
stores the newest message of each kind and schedules at most one pending drain, so a slow loop
sees the latest values, never a backlog (MAVSDK's own asyncio subscriptions queue without
bound). Commands that wait for an ack run on one worker thread this driver owns. Overrides are
sent from the loop (a non-blocking UDP or serial write of ~30 µs).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

from mavsdk import LogLevel, log_subscribe
from mavsdk.asyncio import Configuration, Mavsdk
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
from mavsdk.plugins.param import Param, ParamError, ParamResult

from drivers.config import Autopilot as AutopilotConfig
from drivers.sensor import Sample
from drivers.timing import DeviceClock
from drivers.values import Clock, FlightState

log = logging.getLogger(__name__)

MESSAGES = {  # name → MAVLink id, for SET_MESSAGE_INTERVAL
    "ATTITUDE": 30,
    "VFR_HUD": 74,
    "AOA_SSA": 11020,
    "RC_CHANNELS": 65,
    "SERVO_OUTPUT_RAW": 36,
    "NAV_CONTROLLER_OUTPUT": 62,
    "HEARTBEAT": 0,
}
SET_MESSAGE_INTERVAL = 511
IGNORE, RELEASE_LOW, RELEASE_HIGH = 65535, 0, 65534
# Releases are repeated so one lost datagram does not leave a surface overridden until
# RC_OVERRIDE_TIME.
RELEASE_REPEATS = 3
# Stopping while channels are overridden: how long the link stays up for the trim and release.
HOLD_GRACE_S = 1.0
# The watchdog looks this often (s): link loss is reported within link_timeout_s + this.
WATCH_S = 0.05
# MAVSDK's own log lines kept for the loop to pass on (it may log from any thread).
MAVSDK_LOG = 200


# ArduPlane's custom_mode numbers (HEARTBEAT), for the console and the log.
PLANE_MODES = {
    0: "MANUAL",
    1: "CIRCLE",
    2: "STABILIZE",
    3: "TRAINING",
    4: "ACRO",
    5: "FBWA",
    6: "FBWB",
    7: "CRUISE",
    8: "AUTOTUNE",
    10: "AUTO",
    11: "RTL",
    12: "LOITER",
    13: "TAKEOFF",
    15: "GUIDED",
    17: "QSTABILIZE",
    19: "QLOITER",
    20: "QLAND",
    21: "QRTL",
}


class AutopilotError(RuntimeError):
    """No usable link to the autopilot (the scheduler aborts a run on it)."""


class MessageSeam:
    """MAVSDK's threads → the loop: newest message per name, at most one pending drain. The
    callback takes no lock and logs nothing (docs/hardening.md, *Reliability*): it stores into
    dicts, one atomic operation each under the GIL, and the drain pops what it finds."""

    def __init__(self, loop: asyncio.AbstractEventLoop, deliver: Callable[[dict], None]):
        self._loop, self._deliver = loop, deliver
        self._latest: dict[str, str] = {}
        self._pending = False
        self._received: dict[str, int] = {}

    @property
    def received(self) -> Counter[str]:
        """Messages received by name (a copy; two callback threads counting the same name at
        the same instant may count one)."""
        return Counter(self._received.copy())

    def callback(self, message, _user_data=None) -> None:  # on a MAVSDK thread
        name = message.message_name
        self._latest[name] = message.fields_json
        self._received[name] = self._received.get(name, 0) + 1
        if self._pending:
            return
        self._pending = True
        with contextlib.suppress(RuntimeError):  # a closed loop: we are shutting down
            self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        # Cleared before popping: a message stored after this point either is popped below or
        # schedules the next drain; a second drain scheduled by a race finds nothing to do.
        self._pending = False
        for name in list(self._latest):
            text = self._latest.pop(name, None)
            if text is not None:
                self._deliver(json.loads(text))


class AutopilotLink:
    """Connects, keeps telemetry flowing, watches the link, and sends overrides."""

    def __init__(
        self,
        config: AutopilotConfig,
        clock: Clock,
        *,
        switch_channel: int,
        on_switch: Callable[[int, float], None] | None = None,
        on_state: Callable[[FlightState], None] | None = None,
        on_servos: Callable[[float, dict[int, int]], None] | None = None,
        on_sticks: Callable[[float, dict[int, int]], None] | None = None,
        on_sample: Callable[[Sample], None] | None = None,
        on_link: Callable[[bool, str], None] | None = None,
    ):
        self._cfg, self._clock, self._switch = config, clock, switch_channel
        self._on_switch, self._on_state, self._on_servos = on_switch, on_state, on_servos
        self._on_sticks = on_sticks
        self._on_sample, self._on_link = on_sample, on_link
        self._direct = None
        self._param = None
        self._integer_params: set[str] = set()  # ArduPilot's AP_Int* ones (_get_param)
        self._executor: ThreadPoolExecutor | None = None
        self._seam: MessageSeam | None = None
        self._boot_clock = DeviceClock()
        self._last_message: float | None = None
        self.connected = False
        self.status = "connecting"
        self.counters: Counter[str] = Counter()
        self._held: set[int] = set()  # channels overridden and not yet released
        self.telemetry: dict[str, dict] = {}
        self._state_parts: dict[str, float] = {}
        self.mavsdk_log: deque[str] = deque(maxlen=MAVSDK_LOG)

    @property
    def flight_mode(self) -> str | None:
        """ArduPlane's mode from the last HEARTBEAT (None before one arrived)."""
        heartbeat = self.telemetry.get("HEARTBEAT")
        if heartbeat is None:
            return None
        mode = int(heartbeat.get("custom_mode", -1))
        return PLANE_MODES.get(mode, f"mode {mode}")

    @property
    def received(self) -> Counter[str]:
        """Messages received from MAVSDK by name (before latest-value coalescing)."""
        return self._seam.received if self._seam else Counter()

    # -- lifecycle ------------------------------------------------------------------------

    async def run(self) -> None:
        """Connect and serve until cancelled."""

        def mavsdk_log(level: LogLevel, message: str, _file, _line) -> bool:
            self.mavsdk_log.append(f"{level.name}: {message}")  # deque.append: thread-safe
            return True  # keep MAVSDK off stdout

        log_subscribe(mavsdk_log)
        loop = asyncio.get_running_loop()
        executor = ThreadPoolExecutor(1, thread_name_prefix="mavsdk-command")
        cfg = self._cfg
        mavsdk = Mavsdk(Configuration.create_manual(cfg.system_id, cfg.component_id, True))
        handles = []
        try:
            await mavsdk.add_any_connection(cfg.url)
            system = None
            while system is None:
                system = await mavsdk.first_autopilot(timeout_s=cfg.connect_timeout_s)
                if system is None:
                    self._report(
                        False, f"no autopilot on {cfg.url} after {cfg.connect_timeout_s:g} s"
                    )
            self._direct = MavlinkDirect(system._system)
            self._param = Param(system._system)
            self._executor = executor
            self._seam = MessageSeam(loop, self._deliver)
            handles = [self._direct.subscribe_message(n, self._seam.callback) for n in MESSAGES]
            self._last_message = self._clock.now()
            self._report(True, "connected")
            await self._set_rates(loop, executor)
            await self._watch(loop, executor)
        finally:
            await self._let_go()
            await _drained(loop, executor)
            for handle in handles:
                self._direct.unsubscribe_message(handle)
            self._executor = None
            if self._param is not None:
                self._param.destroy()
                self._param = None
            if self._direct is not None:
                self._direct.destroy()
                self._direct = None
            self.connected = False
            mavsdk.destroy()

    async def _let_go(self) -> None:
        """Stopping (the agent shutting down): while an override is held — a run being ended,
        its trim and release still to go out — keep the link up to HOLD_GRACE_S, so the
        scheduler's trim and release reach the autopilot instead of ArduPilot's timeout."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + HOLD_GRACE_S
        while self._held and self._direct is not None and loop.time() < deadline:
            try:
                await asyncio.sleep(0.01)
            except asyncio.CancelledError:  # cancelled again: stop waiting
                break
        if self._held:
            self.counters["closed_holding_override"] += 1
            log.warning(
                "autopilot link closed while channels %s were overridden", sorted(self._held)
            )

    async def _set_rates(self, loop, executor) -> None:

        cfg = self._cfg
        rates = {
            "ATTITUDE": cfg.attitude_hz,
            "VFR_HUD": cfg.vfr_hud_hz,
            "AOA_SSA": cfg.aoa_hz,
            "RC_CHANNELS": cfg.rc_channels_hz,
            "SERVO_OUTPUT_RAW": cfg.servo_output_hz,
            "NAV_CONTROLLER_OUTPUT": cfg.nav_controller_hz,
        }
        for name, hz in rates.items():
            fields = {
                "command": SET_MESSAGE_INTERVAL,
                "confirmation": 0,
                "param1": MESSAGES[name],
                "param2": round(1e6 / hz),
                "param3": 0,
                "param4": 0,
                "param5": 0,
                "param6": 0,
                "param7": 0,
            }
            command = self._message("COMMAND_LONG", fields)
            try:
                ack = await loop.run_in_executor(executor, self._direct.send_command, command)
                result = json.loads(ack.fields_json or "{}").get("result")
            except Exception as exc:  # MavlinkDirectError and ctypes errors alike: log, go on
                result = repr(exc)
            if result != 0:
                self.counters["rate_refused"] += 1
                log.warning("autopilot: %s at %g Hz not accepted (%s)", name, hz, result)

    async def _watch(self, loop, executor) -> None:
        while True:
            await asyncio.sleep(WATCH_S)
            while self.mavsdk_log:
                log.debug("mavsdk %s", self.mavsdk_log.popleft())
            silent = self._clock.now() - (self._last_message or 0.0)
            if self.connected and silent > self._cfg.link_timeout_s:
                self.counters["link_losses"] += 1
                self._report(False, f"no message from the autopilot for {silent:.2f} s")
            elif not self.connected and silent <= self._cfg.link_timeout_s:
                self._report(True, "link back")
                await self._set_rates(loop, executor)  # a rebooted autopilot forgot them

    def _report(self, up: bool, reason: str) -> None:
        self.connected = up
        self.status = "connected" if up else "lost"
        (log.info if up else log.warning)("autopilot: %s", reason)
        if self._on_link is not None:
            self._on_link(up, reason)

    # -- telemetry ------------------------------------------------------------------------

    def _deliver(self, fields: dict) -> None:
        name = fields.get("message_name", "")
        now = self._clock.now()
        self._last_message = now
        self.telemetry[name] = fields
        boot_ms = fields.get("time_boot_ms")
        if boot_ms is None and "time_usec" in fields:
            boot_ms = fields["time_usec"] / 1000
        t = now if boot_ms is None else self._boot_clock.local(boot_ms / 1000.0, now)
        if name == "RC_CHANNELS":
            pwm = fields.get(f"chan{self._switch}_raw")
            if pwm is not None and self._on_switch is not None:
                self._on_switch(int(pwm), t)
            if self._on_sticks is not None:
                sticks = {
                    ch: int(fields[f"chan{ch}_raw"])
                    for ch in range(1, 19)
                    if f"chan{ch}_raw" in fields
                }
                self._on_sticks(t, sticks)
        elif name == "SERVO_OUTPUT_RAW":
            servos = {
                ch: int(fields[f"servo{ch}_raw"])
                for ch in range(1, 17)
                if f"servo{ch}_raw" in fields
            }
            if self._on_servos is not None:
                self._on_servos(t, servos)
            if self._on_sample is not None and 3 in servos:
                self._on_sample(Sample("autopilot", t, {"throttle": float(servos[3])}))
        elif name in ("ATTITUDE", "VFR_HUD", "AOA_SSA"):
            self._flight_state(name, fields, t)

    def _flight_state(self, name: str, f: dict, t: float) -> None:
        parts = self._state_parts
        if name == "ATTITUDE":
            parts.update(bank=math.degrees(f["roll"]), pitch=math.degrees(f["pitch"]))
        elif name == "VFR_HUD":
            parts.update(airspeed=f["airspeed"], altitude=f["alt"])
        else:
            parts.update(alpha=f["AOA"])
        if name == "ATTITUDE" and len(parts) == 5 and self._on_state is not None:
            self._on_state(
                FlightState(
                    t,
                    parts["bank"],
                    parts["pitch"],
                    parts["airspeed"],
                    parts["alpha"],
                    parts["altitude"],
                )
            )

    # -- parameters -----------------------------------------------------------------------

    async def parameters(self, names: Sequence[str]) -> dict[str, float]:
        """Each parameter's value as the autopilot holds it (PARAM_REQUEST_READ, MAVSDK's
        param plugin on the command thread). AutopilotError names those it did not give."""
        values, missing = {}, []
        for name in names:
            try:
                values[name] = await self._get_param(name)
            except ParamError as exc:
                missing.append(f"{name} ({_why(exc)})")
        if missing:
            raise AutopilotError(f"the autopilot did not give {', '.join(missing)}")
        return values

    async def set_parameters(self, values: Mapping[str, float]) -> dict[str, float]:
        """Set each parameter (PARAM_SET, answered by the autopilot's PARAM_VALUE), then read
        every one back; the values read back. AutopilotError names each one refused, lost or
        read back different (the set may have half happened: the caller reads and reverts).
        After one lost (no answer through MAVSDK's retries) the rest are not sent."""
        failed = []
        for name, value in values.items():
            try:
                await self._set_param(name, value)
                self.counters["params_set"] += 1
            except ParamError as exc:
                self.counters["params_refused"] += 1
                failed.append(f"{name} ({_why(exc)})")
                if exc.result in (ParamResult.TIMEOUT, ParamResult.CONNECTION_ERROR):
                    # Unanswered after MAVSDK's retries: the link is not carrying them, and
                    # each further one would wait as long. The rest are not sent.
                    rest = list(values)[list(values).index(name) + 1 :]
                    if rest:
                        failed.append(f"{', '.join(rest)} not sent")
                    break
        read = {}
        for name in values:
            try:
                read[name] = await self._get_param(name)
            except ParamError as exc:
                failed.append(f"{name} not read back ({_why(exc)})")
        for name, value in read.items():
            wanted = float(values[name])
            if name in self._integer_params:
                wanted = float(round(wanted))
            if not math.isclose(value, wanted, rel_tol=1e-5, abs_tol=1e-6):
                failed.append(f"{name} reads {value:g}, not {wanted:g}")
        if failed:
            raise AutopilotError(f"parameters not set: {'; '.join(dict.fromkeys(failed))}")
        return read

    # ArduPilot's parameters are typed (AP_Float, AP_Int16, AP_Int8…: RLL2SRV_RMAX is an
    # AP_Int16) and its PARAM_VALUE says so; MAVSDK's param plugin answers a float request for
    # an integer one with WRONG_TYPE. So a parameter is asked as a float first and, refused for
    # its type, as an integer, and the integer ones are remembered and set as integers (a
    # design's value rounded: ArduPilot would truncate a float).
    _TYPE_REFUSED = (ParamResult.WRONG_TYPE, ParamResult.TYPE_MISMATCH)

    async def _get_param(self, name: str) -> float:
        if name not in self._integer_params:
            try:
                return float(await self._param_call("get_param_float", name))
            except ParamError as exc:
                if exc.result not in self._TYPE_REFUSED:
                    raise
            self._integer_params.add(name)
        return float(await self._param_call("get_param_int", name))

    async def _set_param(self, name: str, value: float) -> None:
        if name not in self._integer_params:
            try:
                await self._param_call("set_param_float", name, float(value))
                return
            except ParamError as exc:
                if exc.result not in self._TYPE_REFUSED:
                    raise
            self._integer_params.add(name)
        await self._param_call("set_param_int", name, round(float(value)))

    async def _param_call(self, method: str, *args):
        if self._param is None or self._executor is None or not self.connected:
            raise AutopilotError(f"no autopilot link ({self.status})")
        call = getattr(self._param, method)
        return await asyncio.get_running_loop().run_in_executor(self._executor, call, *args)

    # -- the surface sink -----------------------------------------------------------------

    async def command(self, pwm: Mapping[int, int]) -> None:
        """RC_CHANNELS_OVERRIDE with these channels; every other channel left alone."""
        if self._switch in pwm:
            raise AutopilotError(f"channel {self._switch} is the pilot's switch: never overridden")
        self._send_override({ch: int(v) for ch, v in pwm.items()})
        self._held |= set(pwm)
        self.counters["overrides"] += 1

    async def release(self, channels: Sequence[int]) -> None:
        """Give these channels back to the pilot (0 on 1–8, 65534 on 9–18)."""
        values = {ch: RELEASE_LOW if ch <= 8 else RELEASE_HIGH for ch in channels}
        for _ in range(RELEASE_REPEATS):
            self._send_override(values)
        self._held -= set(channels)
        self.counters["releases"] += 1

    def _send_override(self, values: Mapping[int, int]) -> None:
        if self._direct is None or not self.connected:
            raise AutopilotError(f"no autopilot link ({self.status})")
        fields = {
            f"chan{ch}_raw": values.get(ch, IGNORE if ch <= 8 else RELEASE_LOW)
            for ch in range(1, 19)
        }
        self._direct.send_message(self._message("RC_CHANNELS_OVERRIDE", fields))

    def _message(self, name: str, fields: dict) -> MavlinkMessage:
        """Message `name` from us to the autopilot (component 1), addressed in `fields` too."""
        cfg = self._cfg
        return MavlinkMessage(
            message_name=name,
            system_id=cfg.system_id,
            component_id=cfg.component_id,
            target_system_id=cfg.target_system,
            target_component_id=1,
            fields_json=json.dumps(
                {"target_system": cfg.target_system, "target_component": 1, **fields}
            ),
        )


def _why(exc: ParamError) -> str:
    """A param request's failure in words: "timeout", "does not exist"…"""
    return exc.result.name.lower().replace("_", " ")


def _nothing() -> None:
    pass


async def _drained(loop, executor: ThreadPoolExecutor) -> None:
    """The command thread's last command awaited (MAVSDK's own timeout bounds it), then the
    idle thread joined: nothing left running once the driver is done, and the loop never held.
    Cancelled meanwhile, it stops waiting and lets the thread end on its own."""
    try:
        await loop.run_in_executor(executor, _nothing)
    except asyncio.CancelledError:
        executor.shutdown(wait=False, cancel_futures=True)
        raise
    executor.shutdown(wait=True)
