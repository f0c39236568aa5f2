"""An emulated ArduPlane in MANUAL or FBWA, speaking real MAVLink (pymavlink) over UDP.

What it does, as ArduPlane does it (docs/protocols.md, *ArduPlane through MAVSDK*):
- HEARTBEAT at 1 Hz as a fixed-wing ArduPilot (custom mode 0 = MANUAL, armed).
- Telemetry at per-message intervals, changed by MAV_CMD_SET_MESSAGE_INTERVAL (511) with a
  COMMAND_ACK: ATTITUDE, VFR_HUD, AOA_SSA, RC_CHANNELS, SERVO_OUTPUT_RAW, GLOBAL_POSITION_INT,
  NAV_CONTROLLER_OUTPUT (in FBWA the roll and pitch its laws demand).
  Other commands are acknowledged as unsupported (MAVSDK asks a few things on connect).
- RC_CHANNELS_OVERRIDE accepted only from SYSID_MYGCS (255) addressed to this system; channels
  1–8: 0 releases, 65535 leaves alone; 9–18: 65534 releases, 0 and 65535 leave alone. An
  override lapses RC_OVERRIDE_TIME after its last refresh and the pilot's stick is back. The
  excitation switch channel is never overridden, and with RCx_OPTION = 46 (RC override enable)
  a low switch disables all overrides — the pilot's hardware kill.
- MANUAL: servo outputs follow the RC inputs; overridden channels report the override in
  RC_CHANNELS. The outputs drive the JSBSim surfaces through a servo model (transport delay,
  rate limit, travel limit).
- FBWA (custom mode 5), entered by MAV_CMD_DO_SET_MODE or SET_MODE as ArduPlane takes them:
  the roll, pitch and rudder sticks (or their overrides) are the attitude demand and ArduPlane's
  own laws (agent.fbwa, run at its 50 Hz loop) move the surfaces; the throttle stays the
  pilot's. Surfaces go out as ArduPlane's servo outputs do: ±45° of notional travel is
  SERVOn_MIN…SERVOn_MAX about SERVOn_TRIM, where the installer's trim holds the trimmed
  aircraft.
- Parameters by name (PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET → PARAM_VALUE with
  their count and index): FBWA's (agent.fbwa.DEFAULTS), each of ArduPlane's type
  (`PARAM_TYPES`: the rate limits and airspeed limits AP_Int16, TRIM_THROTTLE AP_Int8, the
  rest AP_Float), an integer's value sent as a float as ArduPilot does and a PARAM_SET of one
  stored as its integer (C's conversion: toward zero). A PARAM_SET of a name the vehicle does
  not have gets no answer, as ArduPlane gives none.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from agent.fbwa import DEFAULTS as FBWA_DEFAULTS
from agent.fbwa import LOOP_HZ, TRAVEL_DEG, Fbwa, Sensed
from agent.sim.dataflash import DataFlashWriter

# The FBWA parameters ArduPlane holds as integers (the rest are AP_Float): the rate limits
# (AP_AutoTune.h's ATGains rmax_pos/rmax_neg, AP_PitchController's RMAX_UP/DN), the yaw
# controller's IMAX, and AP_FixedWing's airspeed_min/max (AP_Int16) and throttle_cruise
# (TRIM_THROTTLE, AP_Int8). MAVSDK's param plugin refuses a float request for them.
PARAM_TYPES = {
    "RLL2SRV_RMAX": mavlink.MAV_PARAM_TYPE_INT16,
    "PTCH2SRV_RMAX_UP": mavlink.MAV_PARAM_TYPE_INT16,
    "PTCH2SRV_RMAX_DN": mavlink.MAV_PARAM_TYPE_INT16,
    "YAW2SRV_IMAX": mavlink.MAV_PARAM_TYPE_INT16,
    "AIRSPEED_MIN": mavlink.MAV_PARAM_TYPE_INT16,
    "AIRSPEED_MAX": mavlink.MAV_PARAM_TYPE_INT16,
    "TRIM_THROTTLE": mavlink.MAV_PARAM_TYPE_INT8,
}

log = logging.getLogger(__name__)

CHANNELS = 18
IGNORE, RELEASE_LOW, RELEASE_HIGH = 65535, 0, 65534
MANUAL, FBWA = 0, 5  # ArduPlane's custom mode numbers
MODES = {MANUAL: "MANUAL", FBWA: "FBWA"}
BASE_MODE = (
    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
)
# ArduPlane's heartbeat adds this flag in its stabilised modes.
STABILISED = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
# An RC input's half range (RCn_MAX − RCn_TRIM with ArduPilot's defaults), µs: FBWA's stick is
# (pwm − RCn_TRIM) over it, within ±1. RCn_TRIM is the stick at rest when the radio was
# calibrated, the transmitter's trim included: the emulation takes the pilot's trimmed sticks.
RC_HALF_RANGE = 400
# SERVOn_MIN/MAX about SERVOn_TRIM: ±45° of notional surface is ±500 µs, the simulated
# installation's whole servo travel (config.toml's [excitation.surfaces] min_us/max_us 1000 and
# 2000, where ArduPilot's defaults, 1100 and 1900, would leave a fifth of it unused).
SERVO_HALF_RANGE = 500
# The ISA troposphere's density ratio (1 − ISA_LAPSE h)^ISA_EXPONENT, h in metres: EAS2TAS.
ISA_LAPSE = 2.25577e-5
ISA_EXPONENT = 4.2559
# Default stream intervals (s) before the GCS asks for others; ArduPilot's SRx_ defaults are
# a few Hz.
DEFAULT_INTERVAL = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 0.25,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 0.25,
    mavlink.MAVLINK_MSG_ID_AOA_SSA: 0.25,
    mavlink.MAVLINK_MSG_ID_RC_CHANNELS: 0.25,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 0.25,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.25,
    mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: 0.25,
}
# The onboard log at 50 Hz (ArduPilot's LOG_BITMASK default rates are 25–50 Hz) of the 100 Hz
# autopilot ticks.
DATAFLASH_EVERY = 2
# Entries kept in the wire log (about a minute of overrides at 50 Hz).
WIRE_LOG = 4096
# Output channel → JSBSim control (ArduPlane's default RCMAP / SERVOn_FUNCTION).
OUTPUTS = {1: "aileron", 2: "elevator", 3: "throttle", 4: "rudder"}


# Shaped like RfChannel and drivers/codec.py's CodecStats only: ArduPlane's own parameters.
@dataclass
class Params:
    """The ArduPlane parameters the emulation honours."""

    sysid: int = 1
    sysid_mygcs: int = 255
    rc_override_time_s: float = 3.0
    switch_channel: int = 7
    switch_option_46: bool = True
    switch_high_us: int = 1700
    servo_delay_s: float = 0.02
    servo_rate: float = 4.0
    """Normalised travel per second (±1 is full travel): 0.5 s end to end."""
    servo_travel: float = 1.0
    reversed: dict[int, bool] = field(default_factory=dict)
    fbwa: dict[str, float] = field(default_factory=dict)
    """FBWA's parameters where the aircraft's setup differs from ArduPlane's defaults
    (SCALING_SPEED and the airspeed limits for its speed, PTCH_TRIM_DEG for its trim)."""


# How each servo is linked to JSBSim's control: +1 when a larger PWM moves the control's
# normalised command up. ArduPlane's RC inputs rise for roll right, pitch up, yaw right and more
# throttle (its radio calibration), and in MANUAL a servo output follows its input. JSBSim's
# commands follow FlightGear's sense (measured on the J-3 Cub, Cessna 172 and 182 and PA-28:
# aileron + rolls right, elevator + pitches nose down, rudder + yaws nose left). So the elevator
# and rudder servos are linked the other way round, as an installer fits them for the aircraft
# to answer the sticks; SERVOn_REVERSED (`Params.reversed`) stays 0.
LINKAGE = {1: 1, 2: -1, 3: 1, 4: -1}


def setup(trim: dict[str, float]) -> dict[str, float]:
    """FBWA's parameters as a pilot sets ArduPlane up for an aircraft trimmed at `trim` (the
    plant's state): SCALING_SPEED its trimmed equivalent airspeed, AIRSPEED_MIN and _MAX
    about it (ArduPlane's defaults, 9 to 22 m/s about 15, are a small UAV's), PTCH_TRIM_DEG
    its trimmed pitch (the attitude FBWA holds hands off)."""
    eas = trim["Vt"] / eas_to_tas(trim.get("alt", 0.0))
    return {
        "SCALING_SPEED": round(eas, 1),
        "AIRSPEED_MIN": round(0.6 * eas, 1),
        "AIRSPEED_MAX": round(1.5 * eas, 1),
        "PTCH_TRIM_DEG": round(float(np.degrees(trim["theta"])), 2),
    }


def eas_to_tas(altitude_m: float) -> float:
    """True over equivalent airspeed in the ISA troposphere (ArduPilot's EAS2TAS)."""
    return float((1.0 - ISA_LAPSE * max(altitude_m, 0.0)) ** (-ISA_EXPONENT / 2))


def pwm_to_normalised(channel: int, pwm: float) -> float:
    """A servo output's PWM → its JSBSim command: throttle 1000–2000 µs → 0–1; surfaces
    1500 ± 500 µs → ±1 in the sense of LINKAGE."""
    if OUTPUTS.get(channel) == "throttle":
        return (pwm - 1000.0) / 1000.0
    return LINKAGE.get(channel, 1) * (pwm - 1500.0) / 500.0


def normalised_to_pwm(channel: int, value: float) -> int:
    """Inverse of pwm_to_normalised."""
    if OUTPUTS.get(channel) == "throttle":
        return round(1000 + 1000 * value)
    return round(1500 + 500 * LINKAGE.get(channel, 1) * value)


class ServoModel:
    """A servo: pure delay, then a rate limit, then the travel stops (normalised units)."""

    def __init__(self, delay_s: float, rate: float, travel: float, dt: float, start: float):
        self._queue: deque[float] = deque([start] * max(1, round(delay_s / dt)))
        self._step, self._travel, self.position = rate * dt, travel, start

    def step(self, command: float) -> float:
        self._queue.append(command)
        target = float(np.clip(self._queue.popleft(), -self._travel, self._travel))
        self.position += float(np.clip(target - self.position, -self._step, self._step))
        return self.position


class EmulatedArduPlane(asyncio.DatagramProtocol):
    """See the module docstring. `tick(now, state)` runs it; the datagram side is asyncio's."""

    def __init__(
        self,
        params: Params,
        pilot: Callable[[float], list[int]],
        *,
        dt: float,
        trim: dict[str, float],
        gcs: tuple[str, int] | None = None,
        clock: Callable[[], float] | None = None,
        dataflash: DataFlashWriter | None = None,
    ):
        self.params, self._pilot, self._dt = params, pilot, dt
        self.dataflash = dataflash
        """The onboard log (.bin), as ArduPlane writes it at LOG_RATE; None: no log."""
        self._ticks = 0
        self._clock = clock or (lambda: self._now)
        self.mav = mavlink.MAVLink(None, srcSystem=params.sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self._transport: asyncio.DatagramTransport | None = None
        self.peers: set[tuple[str, int]] = {gcs} if gcs else set()
        self._overrides: dict[int, tuple[int, float]] = {}
        self.default_intervals = dict(DEFAULT_INTERVAL)
        self.intervals = dict(DEFAULT_INTERVAL)
        self._due: dict[int, float] = {}
        self._heartbeat_at = -1.0
        self._now = 0.0
        self._boot = None
        self.counters: Counter[str] = Counter()
        self.link_up = True
        """False: the MAVLink link is cut both ways (a cable or telemetry radio lost)."""
        self.wire: deque[tuple[float, str, object]] = deque(maxlen=WIRE_LOG)
        """What crossed the wire, stamped by the clock: ("override", {channel: value},
        accepted) received, ("switch", pwm) sent in RC_CHANNELS — for the safety tests."""
        start = {ch: trim.get(name, 0.0) for ch, name in OUTPUTS.items()}
        self.servos = {
            ch: ServoModel(
                params.servo_delay_s, params.servo_rate, params.servo_travel, dt, start[ch]
            )
            for ch in OUTPUTS
        }
        self.outputs: dict[int, int] = {ch: normalised_to_pwm(ch, start[ch]) for ch in OUTPUTS}
        # The installer's SERVOn_TRIM: the trimmed aircraft's surface positions; RCn_TRIM: the
        # pilot's sticks at rest.
        self.servo_trim = dict(self.outputs)
        self.rc_trim = {ch: pilot(0.0)[ch - 1] for ch in OUTPUTS}
        self.mode = MANUAL
        self.fbwa = Fbwa(dict(params.fbwa))
        self._fbwa_every = max(1, round(1.0 / (LOOP_HZ * dt)))
        self.drop_param_sets = False
        """True: every PARAM_SET is lost on the way (the link otherwise up), for the tests."""
        self.surfaces: dict[str, float] = {}
        """FBWA's last surface outputs and attitude demand (notional degrees)."""

    @property
    def overrides(self) -> dict[int, tuple[int, float]]:
        """The RC overrides held now, {channel: (PWM, when last refreshed)} (a copy); one
        past RC_OVERRIDE_TIME goes at the next tick, when the pilot gets the channel back."""
        return dict(self._overrides)

    async def reboot(self, silent_s: float = 2.0) -> None:
        """ArduPlane restarting (a brown-out, a watchdog reset): silent both ways for
        `silent_s`, then back with a new boot time and MAVLink sequence, no RC override, and the
        stream rates at their defaults (the GCS's SET_MESSAGE_INTERVAL requests are forgotten).
        The emulation keeps ticking meanwhile (a simplification): with the overrides gone, the
        pilot's sticks drive the servos."""
        self.counters["reboots"] += 1
        self.link_up = False
        self._overrides.clear()
        await asyncio.sleep(silent_s)
        self.mav = mavlink.MAVLink(None, srcSystem=self.params.sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self.intervals = dict(DEFAULT_INTERVAL)
        self._due.clear()
        self._heartbeat_at = -1.0
        self._boot = None
        self.link_up = True

    # -- MAVLink in -----------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if not self.link_up:
            self.counters["cut_in"] += 1
            return
        self.peers.add(addr)
        try:
            messages = self.mav.parse_buffer(data) or []
        except mavlink.MAVError:
            self.counters["bad_packets"] += 1
            return
        for message in messages:
            kind = message.get_type()
            if kind == "RC_CHANNELS_OVERRIDE":
                self._override(message)
            elif kind == "COMMAND_LONG":
                self._command(message, addr)
            elif kind == "SET_MODE":
                if message.target_system == self.params.sysid:
                    self.set_mode(int(message.custom_mode))
            elif kind.startswith("PARAM_"):
                self._param(message, addr)

    def _override(self, m) -> None:
        p = self.params
        if m.get_srcSystem() != p.sysid_mygcs or m.target_system != p.sysid:
            self.counters["overrides_wrong_sysid"] += 1
            return
        values = {ch: getattr(m, f"chan{ch}_raw") for ch in range(1, CHANNELS + 1)}
        values = {
            ch: v for ch, v in values.items() if v != IGNORE and not (ch > 8 and v == RELEASE_LOW)
        }
        if p.switch_option_46 and self._pilot(self._now)[p.switch_channel - 1] < p.switch_high_us:
            self.counters["overrides_switch_low"] += 1
            self.wire.append((self._clock(), "override", values, False))
            return
        self.counters["overrides"] += 1
        self.wire.append((self._clock(), "override", values, True))
        for ch in range(1, CHANNELS + 1):
            value = getattr(m, f"chan{ch}_raw")
            if ch == p.switch_channel:
                continue  # the pilot's switch is never overridden
            released = value == RELEASE_LOW if ch <= 8 else value == RELEASE_HIGH
            ignored = value == IGNORE if ch <= 8 else value in (IGNORE, RELEASE_LOW)
            if released:
                self._overrides.pop(ch, None)
            elif not ignored:
                self._overrides[ch] = (value, self._now)

    def _command(self, m, addr) -> None:
        if m.target_system != self.params.sysid:
            return
        result = mavlink.MAV_RESULT_UNSUPPORTED
        if m.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id, interval_us = int(m.param1), m.param2
            if interval_us < 0:
                self.intervals.pop(msg_id, None)
            elif interval_us == 0:
                if msg_id in DEFAULT_INTERVAL:
                    self.intervals[msg_id] = DEFAULT_INTERVAL[msg_id]
            else:
                self.intervals[msg_id] = interval_us * 1e-6
            result = mavlink.MAV_RESULT_ACCEPTED
        elif m.command == mavlink.MAV_CMD_DO_SET_MODE:
            custom = int(m.param1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            ok = bool(custom) and self.set_mode(int(m.param2))
            result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED
        ack = self.mav.command_ack_encode(
            m.command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent()
        )
        self._send(ack, [addr])

    def set_mode(self, mode: int) -> bool:
        """Enter `mode` (False: not one this vehicle flies). FBWA starts from its laws'
        reset state, as ArduPlane's mode change resets the controllers."""
        if mode not in MODES:
            self.counters["modes_refused"] += 1
            return False
        if mode != self.mode:
            self.mode = mode
            self.fbwa = Fbwa(dict(self.fbwa.params))
            self.counters["mode_changes"] += 1
            if self.dataflash is not None and self._boot is not None:
                us = int((self._now - self._boot) * 1e6)
                self.dataflash.write("MODE", TimeUS=us, Mode=mode, ModeNum=mode)
        return True

    def _param(self, m, addr) -> None:
        """PARAM_REQUEST_LIST / _READ / PARAM_SET, answered with PARAM_VALUE as ArduPlane
        does: each name with its index and the count."""
        if getattr(m, "target_system", self.params.sysid) != self.params.sysid:
            return
        names = list(FBWA_DEFAULTS)
        kind = m.get_type()
        if kind == "PARAM_REQUEST_LIST":
            for name in names:
                self._param_value(name, names, addr)
            return
        if kind == "PARAM_REQUEST_READ":
            name = m.param_id if m.param_index < 0 else None
            if name is None and 0 <= m.param_index < len(names):
                name = names[m.param_index]
            if name in FBWA_DEFAULTS:
                self._param_value(name, names, addr)
            return
        if kind == "PARAM_SET":
            if self.drop_param_sets:
                self.counters["params_dropped"] += 1
                return
            name = m.param_id
            if name not in FBWA_DEFAULTS or not np.isfinite(m.param_value):
                self.counters["params_refused"] += 1
                return
            value = float(m.param_value)
            if name in PARAM_TYPES:  # an AP_Int*: ArduPilot's set_float converts as C does
                value = float(int(value))
            self.fbwa.set(name, value)
            self.counters["params_set"] += 1
            self._param_value(name, names, None)  # ArduPlane announces a change to every GCS

    def _param_value(self, name: str, names: list[str], addr) -> None:
        message = self.mav.param_value_encode(
            name.encode(),
            float(self.fbwa.params[name]),
            PARAM_TYPES.get(name, mavlink.MAV_PARAM_TYPE_REAL32),
            len(names),
            names.index(name),
        )
        self._send(message, [addr] if addr else None)

    # -- the vehicle ----------------------------------------------------------------------

    def rc_inputs(self, now: float) -> list[int]:
        """What the flight code sees on each RC channel: override if live, else the pilot."""
        rc = list(self._pilot(now))
        timeout = self.params.rc_override_time_s
        for ch, (value, when) in list(self._overrides.items()):
            if now - when > timeout:
                del self._overrides[ch]  # lapsed: the pilot has the channel again
                self.counters["override_timeouts"] += 1
            else:
                rc[ch - 1] = value
        return rc

    def tick(self, now: float, state: dict[str, float]) -> dict[str, float]:
        """Advance one step: servo outputs (MANUAL: RC in), servo model, telemetry out.
        Returns the normalised commands for the plant."""
        self._now = now
        if self._boot is None:
            self._boot = now
        rc = self.rc_inputs(now)
        commands = {}
        if self.mode == FBWA and self._ticks % self._fbwa_every == 0:
            self._stabilise(state, rc)
        for ch, name in OUTPUTS.items():
            if self.mode == MANUAL or name == "throttle":
                self.outputs[ch] = rc[ch - 1]
            command = pwm_to_normalised(ch, self.outputs[ch])
            if self.params.reversed.get(ch):
                command = -command
            commands[name] = self.servos[ch].step(command)
        self._telemetry(now, state, rc)
        if self.dataflash is not None and self._ticks % DATAFLASH_EVERY == 0:
            self._log(now, state, rc)
        self._ticks += 1
        return commands

    def _stabilise(self, s: dict[str, float], rc: list[int]) -> None:
        """One loop of FBWA's laws: the sticks' attitude demand, the surfaces out (µs)."""

        def stick(ch: int) -> float:
            return float(np.clip((rc[ch - 1] - self.rc_trim[ch]) / RC_HALF_RANGE, -1.0, 1.0))

        eas2tas = eas_to_tas(s.get("alt", 0.0))
        sensed = Sensed(
            phi=s["phi"],
            theta=s["theta"],
            p=s["p"],
            q=s["q"],
            r=s["r"],
            eas=s["Vt"] / eas2tas,
            eas2tas=eas2tas,
            ay=s.get("ay", 0.0),
        )
        roll, pitch = self.fbwa.demands(stick(1), stick(2), s["theta"], s["phi"])
        out = self.fbwa.step(
            sensed, roll_deg=roll, pitch_deg=pitch, rudder_stick=stick(4), dt=1.0 / LOOP_HZ
        )
        for ch, degrees in ((1, out.aileron), (2, out.elevator), (4, out.rudder)):
            self.outputs[ch] = round(self.servo_trim[ch] + degrees / TRAVEL_DEG * SERVO_HALF_RANGE)
        self.surfaces = {
            "aileron": out.aileron,
            "elevator": out.elevator,
            "rudder": out.rudder,
            "roll_demand": out.roll_demand_deg,
            "pitch_demand": out.pitch_demand_deg,
        }

    def _log(self, now: float, s: dict[str, float], rc: list[int]) -> None:
        """ATT, IMU, ARSP, AOA, XKF1, RCIN and RCOU, as ArduPlane logs them (degrees, SI
        units)."""
        log, us = self.dataflash, int((now - self._boot) * 1e6)
        if self._ticks == 0:
            log.write("MODE", TimeUS=us, Mode=self.mode, ModeNum=self.mode)
        deg = 180.0 / np.pi
        log.write(
            "ATT",
            TimeUS=us,
            Roll=s["phi"] * deg,
            Pitch=s["theta"] * deg,
            Yaw=(s["psi"] * deg) % 360.0,
        )
        # Column by column, like ATT above: ArduPlane's IMU names are not our channel names.
        log.write(
            "IMU",
            TimeUS=us,
            GyrX=s["p"],
            GyrY=s["q"],
            GyrZ=s["r"],
            AccX=s["ax"],
            AccY=s["ay"],
            AccZ=s["az"],
            GH=1,
            AH=1,
        )
        log.write("ARSP", TimeUS=us, Airspeed=s["Vt"], U=1, H=1, Pri=1)
        log.write("AOA", TimeUS=us, AOA=s["alpha"] * deg, SSA=s["beta"] * deg)
        log.write(
            "XKF1",
            TimeUS=us,
            C=0,
            Roll=s["phi"] * deg,
            Pitch=s["theta"] * deg,
            Yaw=(s["psi"] * deg) % 360.0,
            VN=s["vn"],
            VE=s["ve"],
            VD=s["vd"],
        )
        log.write("RCIN", TimeUS=us, **{f"C{ch}": rc[ch - 1] for ch in range(1, 15)})
        log.write("RCOU", TimeUS=us, **{f"C{ch}": self.outputs.get(ch, 0) for ch in range(1, 15)})

    def _telemetry(self, now: float, s: dict[str, float], rc: list[int]) -> None:
        if now - self._heartbeat_at >= 1.0:
            self._heartbeat_at = now
            self._send(
                self.mav.heartbeat_encode(
                    mavlink.MAV_TYPE_FIXED_WING,
                    mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                    BASE_MODE | (STABILISED if self.mode == FBWA else 0),
                    self.mode,
                    mavlink.MAV_STATE_ACTIVE,
                    3,
                )
            )
        boot_ms = int((now - self._boot) * 1000) & 0xFFFFFFFF
        for msg_id, interval in self.intervals.items():
            due = self._due.get(msg_id, now)
            if now + self._dt / 2 < due:  # sent at the tick nearest its due time
                continue
            self._due[msg_id] = max(due + interval, now - interval)  # no burst after a stall
            message = self._message(msg_id, boot_ms, s, rc)
            if message is not None:
                self._send(message)

    def _message(self, msg_id: int, boot_ms: int, s: dict[str, float], rc: list[int]):
        m = self.mav
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            return m.attitude_encode(
                boot_ms, s["phi"], s["theta"], s["psi"], s["p"], s["q"], s["r"]
            )
        if msg_id == mavlink.MAVLINK_MSG_ID_VFR_HUD:
            heading, throttle = int(np.degrees(s["psi"]) % 360), round(100 * s["throttle"])
            ground = float(np.hypot(s["vn"], s["ve"]))
            return m.vfr_hud_encode(s["Vt"], ground, heading, throttle, s["alt"], -s["vd"])
        if msg_id == mavlink.MAVLINK_MSG_ID_AOA_SSA:
            return m.aoa_ssa_encode(boot_ms * 1000, np.degrees(s["alpha"]), np.degrees(s["beta"]))
        if msg_id == mavlink.MAVLINK_MSG_ID_RC_CHANNELS:
            self.wire.append((self._clock(), "switch", rc[self.params.switch_channel - 1]))
            return m.rc_channels_encode(boot_ms, CHANNELS, *rc, 255)
        if msg_id == mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW:
            servos = [self.outputs.get(ch, 0) for ch in range(1, 17)]
            return m.servo_output_raw_encode((boot_ms * 1000) & 0xFFFFFFFF, 0, *servos)
        if msg_id == mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT:
            # The attitude its laws demand (ArduPlane's nav_roll_cd, nav_pitch_cd); outside
            # FBWA nothing is demanded, and the attitude flown is sent.
            fbwa = self.mode == FBWA and "roll_demand" in self.surfaces
            roll = self.surfaces["roll_demand"] if fbwa else np.degrees(s["phi"])
            pitch = self.surfaces["pitch_demand"] if fbwa else np.degrees(s["theta"])
            heading = int(np.degrees(s["psi"]) % 360)
            return m.nav_controller_output_encode(roll, pitch, heading, heading, 0, 0.0, 0.0, 0.0)
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return m.global_position_int_encode(
                boot_ms,
                int(s["lat"] * 1e7),
                int(s["lon"] * 1e7),
                int(s["alt"] * 1000),
                int(s["alt"] * 1000),
                int(s["vn"] * 100),
                int(s["ve"] * 100),
                int(s["vd"] * 100),
                int(np.degrees(s["psi"]) % 360 * 100),
            )
        return None

    def _send(self, message, peers=None) -> None:
        if self._transport is None or self._transport.is_closing():
            return
        if not self.link_up:
            self.counters["cut_out"] += 1
            return
        data = message.pack(self.mav)
        for peer in peers or self.peers:
            self._transport.sendto(data, peer)
        self.counters["sent"] += 1
