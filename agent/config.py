"""The validated configuration tree: pydantic models of `config.toml`.

Every section is frozen and forbids unknown keys, so a typo is an error rather than a silently
ignored setting. Loaded once at start-up and passed down; there are no global settings.
"""

from __future__ import annotations

import itertools
import os
import tomllib
import types
import typing
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from agent.channels import AXIS_SETS, INPUT_ROLES, NAVIGATION_ROLES, OUTPUT_ROLES, POWER_ROLES
from drivers.config import (  # the devices' sections are the drivers'
    AirDataPort,
    Autopilot,
    Calibration,
    Section,
    Sensors,
    SerialPort,
    SurfacePort,
    VectorNav,
)

__all__ = ["AirDataPort", "Autopilot", "Calibration", "SerialPort", "SurfacePort", "VectorNav"]


def _auto_or_count(value: object) -> object:
    if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        return value
    raise ValueError(f'must be "auto" or an integer ≥ 1, got {value!r}')


AutoOrCount = Annotated[int | Literal["auto"], BeforeValidator(_auto_or_count)]

# The largest decimation factor. Its anti-alias filter has 20 taps per unit of the factor,
# and each record needs 40 samples per unit; beyond this the filter alone would take
# gigabytes. The identification core holds the same bound (agent.ident.preprocess, which
# this layer may not import; tests/test_config.py checks the two agree).
MAX_DECIMATION = 1000


def _decimation(value: object) -> object:
    value = _auto_or_count(value)
    if isinstance(value, int) and value > MAX_DECIMATION:
        raise ValueError(f'must be "auto" or an integer from 1 to {MAX_DECIMATION}, got {value!r}')
    return value


Decimation = Annotated[int | Literal["auto"], BeforeValidator(_decimation)]
Name = Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$")]


class Channels(Section):
    """Which recorded column or signal carries each channel role."""

    throttle: Name = "throttle"
    """Throttle command (µs of PWM in the thesis's models)."""
    elevator: Name = "elevator"
    """Elevator deflection δE, degrees, ganged as ½(δE_L + δE_R) (thesis eq. 3.1)."""
    aileron: Name = "aileron"
    """Aileron deflection δA, degrees, ganged as ½(δA_R − δA_L) (thesis eq. 3.1)."""
    rudder: Name = "rudder"
    """Rudder deflection δR, degrees."""
    rpm: Name = "rpm"
    """Measured engine speed, rpm: given as an input, the engine's known input in place of the
    throttle's command (offline identification)."""
    thrust: Name = "thrust"
    """Measured thrust, N: as rpm."""
    airspeed: Name = "Vt"
    """True airspeed V_T, m/s."""
    alpha: Name = "alpha"
    """Angle of attack α, rad."""
    q: Name = "q"
    """Body pitch rate q, rad/s."""
    theta: Name = "theta"
    """Pitch attitude θ, rad."""
    beta: Name = "beta"
    """Sideslip angle β, rad."""
    p: Name = "p"
    """Body roll rate p, rad/s."""
    r: Name = "r"
    """Body yaw rate r, rad/s."""
    phi: Name = "phi"
    """Bank angle φ, rad."""
    psi: Name = "psi"
    """Heading ψ from the INS, rad (with vn, ve, vd: the wind, for the aircraft method)."""
    vn: Name = "vn"
    """INS velocity north, m/s."""
    ve: Name = "ve"
    """INS velocity east, m/s."""
    vd: Name = "vd"
    """INS velocity down, m/s."""

    @model_validator(mode="after")
    def _distinct(self) -> Channels:
        roles = INPUT_ROLES + POWER_ROLES + OUTPUT_ROLES + NAVIGATION_ROLES
        names = [getattr(self, role) for role in roles]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"each channel needs its own name; repeated: {', '.join(repeated)}")
        return self

    def axis_set(
        self, axes: str, controls: Iterable[str] | None = None
    ) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(input names, output names) of an axis set: lateral, longitudinal or full; with
        `controls` (the aircraft's, by role), only the inputs among them: a glider's
        longitudinal axis has no throttle."""
        inputs, outputs = AXIS_SETS[axes]
        if controls is not None:
            have = set(controls)
            inputs = tuple(r for r in inputs if r in have)
        return tuple(getattr(self, r) for r in inputs), tuple(getattr(self, r) for r in outputs)

    def navigation(self) -> tuple[str, ...]:
        """The names of the INS heading and velocity channels (NAVIGATION_ROLES order)."""
        return tuple(getattr(self, role) for role in NAVIGATION_ROLES)

    def role_of(self, name: str) -> str | None:
        """The role a column name carries, or None."""
        for role in INPUT_ROLES + POWER_ROLES + OUTPUT_ROLES:
            if getattr(self, role) == name:
                return role
        return None


class IdentificationConfig(Section):
    """How models are identified (OKID → ERA → modes → fit), onboard and offline."""

    axes: Literal["lateral", "longitudinal", "full"] = "lateral"
    """Axis set where nothing else says which: lateral (aileron, rudder → β, p, r, φ),
    longitudinal (throttle, elevator → V, α, q, θ) or full (all four → all eight). Onboard an
    excitation is identified on its plan's axes unless the ground chose axes; this one is for
    the periodic identification (no plan) and offline analysis."""
    channels: Channels = Channels()
    """Names of the recorded channels for each role."""
    markov: AutoOrCount = "auto"
    """Markov parameters p of the OKID regression; "auto" picks p from 1…markov_max by the
    simulation fit of the identified model."""
    markov_max: int = Field(30, ge=1, le=200)
    """Largest p the automatic choice tries."""
    order: AutoOrCount = "auto"
    """Model order n; "auto" reads it from the gap in the Hankel singular values."""
    order_max: int = Field(20, ge=1, le=100)
    """Largest order the automatic choice accepts."""
    trim_seconds: float = Field(0.5, ge=0.0)
    """Trim is the mean of the first trim_seconds of each record (trimmed flight before the
    excitation), subtracted from inputs and outputs; 0 disables trim removal."""
    air_angles: Literal["auto", "vanes", "synthesised"] = "auto"
    """Where α and β come from: "vanes" (as recorded), "synthesised" (from the INS's velocity,
    the attitude and an estimated wind, for an aircraft whose air data measures the airspeed
    only: agent.ident.aircraft.airangles), or "auto": the vanes' where a record has them,
    else synthesised (docs/identification.md, *Without vanes*)."""
    estimate_d: bool = False
    """Estimate the feed-through D; false forces D = 0, a strictly proper model (thesis §4.1.3)."""
    regularization: float = Field(0.0, ge=0.0, lt=1.0)
    """Tikhonov weight ρ of the OKID least squares, relative to the largest singular value
    of the normalised regression; 0 is plain least squares."""
    hankel_blocks: int | None = Field(None, ge=2, le=500)
    """Block rows (= columns) of the ERA Hankel matrix; unset: 20, more if order_max needs."""
    decimation: Decimation = "auto"
    """Decimation factor after the anti-alias filter, 1 to 1000; "auto" brings the rate down
    to 25 × the band of interest; 1 keeps the record rate."""
    band_hz: float | None = Field(None, ge=0.01, le=500.0)
    """Band of interest in Hz, 0.01–500 (an aircraft's slowest named mode, the phugoid, is
    above 0.01 Hz); unset: where 99 % of every input's power lies (≥ 0.5 Hz)."""
    held_inputs: bool | Literal["auto"] = "auto"
    """true: inputs are held between samples (commands; a zero-order hold). false: they are
    samples of continuously varying signals. "auto": the agent's own recordings (onboard, and
    its flight logs replayed by `sysid analyze`) are the surface potentiometers' samples of
    moving surfaces, so not held; other records' (`sysid identify` on CSV) by their data: held
    where every moved input is a staircase or carries no sensor noise (a command), sampled
    where one carries a sensor's noise (a measured position); the result says which."""
    smoothing_s: float | None = Field(None, gt=0.0)
    """Savitzky–Golay smoothing window in seconds (cubic), on inputs and outputs; unset: none."""
    method: Literal["auto", "time", "frequency", "aircraft"] = "auto"
    """"auto": "aircraft" when the outputs are an axis's four (any axes set) and none of
    markov, order or a decimation other than 1 is set, else "time";
    "time": OKID from the time-domain regression; "frequency": OKID from averaged spectra and
    the frequency response over whole excitation periods (thesis §4.3.1); "aircraft":
    decoupled longitudinal and lateral models, every state measured, fitted in the frequency
    domain (equation error, then output error; agent.ident.aircraft)."""
    period_s: float | None = Field(None, gt=0.0)
    """Excitation period for the frequency method; unset: detected from the inputs."""
    noise_model: Literal["auto", "output", "innovation"] = "auto"
    """Refinement criterion: "output" error (white sensor noise), "innovation" (prediction
    error of the Kalman predictor: turbulence as process noise), or "auto": output error,
    switching to the innovation form when its residuals are coloured and its fit poor."""
    refine: bool = True
    """Refine the OKID/ERA model by output error (maximum likelihood) and report Cramér–Rao
    standard errors; false reports the OKID/ERA model as is."""

    @model_validator(mode="after")
    def _aircraft_takes_no_decimation(self) -> IdentificationConfig:
        if self.method == "aircraft" and self.decimation not in ("auto", 1):
            raise ValueError(
                f'method "aircraft" fits the spectra at the record\'s own rate and takes no '
                f'decimation (given {self.decimation}): set decimation = "auto", or method = '
                '"time" or "frequency"'
            )
        return self


class Surface(Section):
    """One excited control (surface or throttle): its RC channel, calibration and limits.

    Command = trim + direction × us_per_unit × value, where value is in the surface's unit
    from trim; commands are clamped to [min_us, max_us].
    """

    channel: int = Field(ge=1, le=16)
    """RC channel (1–16) the autopilot drives this control from (ArduPlane RCMAP)."""
    unit: Literal["deg", "percent"] = "deg"
    """Unit of plan amplitudes for this control: surface degrees, or percent for throttle."""
    us_per_unit: float = Field(gt=0.0, le=200.0)
    """PWM microseconds per degree (or per percent) of this control."""
    direction: Literal[1, -1] | None = None
    """+1 when a larger PWM on the RC channel moves the control in its positive sense, −1 when
    it moves it the other way. Positive is the thesis's (eq. 3.1, Klein and Morelli): δA right
    trailing edge down (rolls left), δE trailing edge down (pitches down), δR trailing edge
    left (yaws left), more throttle. Unset: ArduPlane's sense for the role (its RC inputs rise
    for roll right, pitch up, yaw right and more throttle), so −1 for aileron, elevator and
    rudder and +1 for throttle."""
    min_us: int = Field(1000, ge=800, le=2200)
    """Lowest PWM ever commanded on this channel."""
    max_us: int = Field(2000, ge=800, le=2200)
    """Highest PWM ever commanded on this channel."""
    max_amplitude: float = Field(gt=0.0)
    """Envelope: the largest excitation deflection from trim a plan may ask, in the unit."""
    rate_limit: float = Field(gt=0.0)
    """Servo model: slew rate, unit per second; faster signals are distorted (warning)."""
    travel: float = Field(gt=0.0)
    """Servo model: deflection reachable each side of neutral, in the unit (warning)."""

    @model_validator(mode="after")
    def _ordered(self) -> Surface:
        if self.min_us >= self.max_us:
            raise ValueError(f"min_us ({self.min_us}) must be below max_us ({self.max_us})")
        return self


# A control's `direction` when its table leaves it unset: ArduPlane's RC input sense (roll right,
# pitch up, yaw right: each a negative deflection by eq. 3.1; more throttle).
ARDUPLANE_DIRECTION = {"aileron": -1, "elevator": -1, "rudder": -1, "throttle": 1}


def _default_surfaces() -> dict[str, Surface]:
    # ArduPlane's default RCMAP: roll 1, pitch 2, throttle 3, yaw 4.
    deg = {"us_per_unit": 20.0, "max_amplitude": 10.0, "rate_limit": 200.0, "travel": 25.0}
    return {
        "aileron": Surface(channel=1, direction=ARDUPLANE_DIRECTION["aileron"], **deg),
        "elevator": Surface(channel=2, direction=ARDUPLANE_DIRECTION["elevator"], **deg),
        "throttle": Surface(
            channel=3,
            direction=ARDUPLANE_DIRECTION["throttle"],
            unit="percent",
            us_per_unit=10.0,
            max_amplitude=30.0,
            rate_limit=400.0,
            travel=50.0,
        ),
        "rudder": Surface(channel=4, direction=ARDUPLANE_DIRECTION["rudder"], **deg),
    }


class Envelope(Section):
    """Limits enforced onboard whatever the ground asks: a plan outside them is refused, and a
    run that leaves them is aborted (trim, then release)."""

    max_bank_deg: float = Field(45.0, gt=0.0, le=90.0)
    """Largest |bank angle| during a run."""
    max_pitch_deg: float = Field(25.0, gt=0.0, le=90.0)
    """Largest |pitch attitude| during a run."""
    min_airspeed: float = Field(12.0, ge=0.0)
    """Lowest airspeed during a run, m/s (stall margin)."""
    max_airspeed: float = Field(35.0, gt=0.0)
    """Highest airspeed during a run, m/s."""
    max_alpha_deg: float = Field(12.0, gt=0.0, le=45.0)
    """Largest angle of attack during a run."""
    max_altitude_loss_m: float = Field(40.0, gt=0.0)
    """Excursion limit: the largest height lost since the run started."""
    max_duration_s: float = Field(90.0, gt=0.0, le=600.0)
    """Longest plan accepted (while overridden, the pilot's stick on excited axes is unseen)."""

    @model_validator(mode="after")
    def _speeds(self) -> Envelope:
        if self.min_airspeed >= self.max_airspeed:
            raise ValueError("min_airspeed must be below max_airspeed")
        return self


class Sizing(Section):
    """Plans sized to the aircraft's response before arming (agent/sizing.py,
    docs/excitation.md): each control's amplitude brings its predicted response to these
    targets, from the aircraft's own model; with no model yet, a build-up run."""

    bank_deg: float = Field(15.0, gt=0.0, le=60.0)
    """Largest bank angle change a plan is sized for, degrees."""
    airspeed_pct: float = Field(5.0, gt=0.0, le=30.0)
    """Largest airspeed change, percent of the trim airspeed."""
    alpha_deg: float = Field(3.0, gt=0.0, le=15.0)
    """Largest angle-of-attack change, degrees (the linear range of the lift curve)."""
    beta_deg: float = Field(5.0, gt=0.0, le=20.0)
    """Largest sideslip, degrees."""
    pitch_deg: float = Field(10.0, gt=0.0, le=45.0)
    """Largest pitch attitude change, degrees."""
    load_factor: float = Field(0.5, gt=0.0, le=3.0)
    """Largest load factor change, g."""
    build_up: float = Field(0.25, gt=0.0, le=1.0)
    """With no model of the aircraft yet, the share of the plan's amplitudes flown: that run
    is the calibration whose model sizes the next."""
    max_growth: float = Field(2.0, ge=1.0, le=10.0)
    """A control's sized amplitude is at most this many times the largest deflection in the
    data its model was identified from (amplitude build-up)."""
    max_factor: float = Field(1.0, gt=0.0, le=10.0)
    """The largest factor on a plan's own amplitudes: 1 never flies more than the plan asks
    (the response targets only take amplitude away); above 1 a weakly responding aircraft is
    excited harder, up to the targets and max_amplitude."""


class Excitation(Section):
    """The excitation scheduler: command rate, staleness, trim capture, controls, envelope."""

    rate_hz: float = Field(50.0, ge=50.0, le=100.0)
    """Command rate of RC overrides during a run (thesis: 50–100 Hz)."""
    stale_s: float = Field(0.5, gt=0.0, le=5.0)
    """Flight state or RC switch data older than this aborts a run (and refuses a start)."""
    trim_window_s: float = Field(0.5, gt=0.0, le=10.0)
    """Trim = median servo output over this window just before the run starts."""
    switch_channel: int = Field(7, ge=1, le=18)
    """RC channel of the pilot's excitation switch (read only, never overridden)."""
    switch_high_us: int = Field(1700, ge=800, le=2200)
    """The switch reads high at or above this PWM."""
    surfaces: dict[str, Surface] = Field(default_factory=_default_surfaces)
    """Controls that plans may excite, keyed by role: aileron, elevator, rudder, throttle."""
    envelope: Envelope = Envelope()
    """Onboard limits on plans and on the aircraft during a run."""
    sizing: Sizing = Sizing()
    """Targets and build-up of the plans' sizing to the aircraft's response."""

    @field_validator("surfaces")
    @classmethod
    def _directions(cls, surfaces: dict[str, Surface]) -> dict[str, Surface]:
        return {
            role: s
            if s.direction is not None
            else s.model_copy(update={"direction": ARDUPLANE_DIRECTION.get(role, 1)})
            for role, s in surfaces.items()
        }

    @model_validator(mode="after")
    def _channels(self) -> Excitation:
        unknown = sorted(set(self.surfaces) - set(INPUT_ROLES))
        if unknown:
            raise ValueError(
                f"unknown control {', '.join(unknown)}; controls are {', '.join(INPUT_ROLES)}"
            )
        used = [s.channel for s in self.surfaces.values()]
        if len(set(used)) != len(used):
            raise ValueError("each control needs its own RC channel")
        if self.switch_channel in used:
            raise ValueError(
                f"switch_channel {self.switch_channel} is also a control's channel; the pilot's "
                "switch is never overridden"
            )
        return self


class Recorder(Section):
    """Fixed-rate frames over the sensor channels, the ring buffer, and the logs."""

    rate_hz: float = Field(100.0, ge=1.0, le=1000.0)
    """Frame rate (the thesis logs at 100 Hz)."""
    capacity_s: float = Field(600.0, ge=10.0, le=7200.0)
    """Ring buffer length: the most recent capacity_s seconds of frames stay in memory."""
    delay_s: float = Field(0.25, ge=0.0, le=1.0)
    """Frames are assembled this long after their time, so samples just after it (for
    interpolation) and late arrivals are in."""
    hold_s: float = Field(3.0, ge=1.0, le=5.0)
    """A frame whose samples are later than delay_s (a loop held up by a busy CPU, a device's
    backlog read after it) waits for them up to this long after its time, then is recorded
    with what came; a channel silent for longer holds nothing back."""
    max_age_s: float = Field(0.1, gt=0.0, le=10.0)
    """A channel whose newest sample is older than this at a frame time is recorded empty
    (NaN) there; its age is recorded either way."""
    channels: tuple[str, ...] | None = None
    """Channels to record (unset: every sensor channel, docs/sensors.md)."""
    log_dir: str = "logs"
    """Directory of the flight, excitation and execution logs."""
    excitation_margin_s: float = Field(2.0, ge=0.0, le=60.0)
    """Data kept before and after an excitation window in its input/output log."""

    @model_validator(mode="after")
    def _known(self) -> Recorder:
        from agent.channels import SENSOR_CHANNELS

        unknown = [c for c in self.channels or () if c not in SENSOR_CHANNELS]
        if unknown:
            raise ValueError(f"unknown channels {unknown}; known: {list(SENSOR_CHANNELS)}")
        return self


def _address(value: object) -> object:
    if isinstance(value, str) and len(value) == 16:
        try:
            bytes.fromhex(value)
            return value.upper()
        except ValueError:
            pass
    raise ValueError(f"a 64-bit XBee address is 16 hex digits (SH then SL), got {value!r}")


Address = Annotated[str, BeforeValidator(_address)]


class Link(Section):
    """The XBee link between the aircraft and the ground station."""

    port: str = "/dev/ttyUSB0"
    """Serial port of this end's XBee (API mode 1 or 2: digi-xbee finds out which)."""
    baud: int = Field(115200, ge=1200, le=921600)
    """The XBee's serial baud rate (BD)."""
    peer: Address | None = None
    """The other end's 64-bit address: frames go to it, and only frames from it are
    accepted (the allow-list); unset: the link is not started."""
    key_file: str = "link.key"
    """File holding the shared HMAC key as hex (32 random bytes; keep it mode 0600)."""
    counter_file: str = "link.counter"
    """Where this end reserves its frame counters (never reused under the key)."""
    seen_file: str = "link.seen"
    """Where this end keeps the highest counter accepted from the peer (replays refused
    across restarts)."""
    require_encryption: bool = False
    """Refuse a radio whose AES encryption is off (AT EE = 0): with it off, any node on the
    network can change the module's settings by Remote AT commands. false: a warning at each
    open (and the count in the health log)."""
    heartbeat_s: float = Field(1.0, gt=0.0, le=60.0)
    """A heartbeat goes out when nothing else was sent for this long."""
    deadline_s: float = Field(3.0, gt=0.0, le=120.0)
    """The link is down when no authenticated frame arrived for this long."""
    command_max_age_s: float = Field(10.0, ge=1.0, le=300.0)
    """The aircraft refuses a command (anything but an Abort) sent longer ago than this,
    with the reason, so a command jammed on the way and injected later is never obeyed late.
    The age is read on the aircraft's own clock (the ground says what that clock read when
    it queued the command, from the aircraft's last message; the clocks need not agree), so
    it includes up to one of the aircraft's status intervals. Retries of a command over a
    lossy link count from its first sending."""


MAKE_KEY = "sysid keygen {path}"


def load_key(path: str | Path) -> bytes:
    """The link key from its file (hex); ValueError with what to do on every problem."""
    path = Path(path)
    make = MAKE_KEY.format(path=path)
    try:
        text = path.read_text().strip()
    except (OSError, ValueError) as exc:  # a binary file is a UnicodeDecodeError
        raise ValueError(
            f"{path}: cannot read the link key ({getattr(exc, 'strerror', None) or exc}); "
            f"make one with: {make}"
        ) from exc
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise ValueError(
            f"{path}: the link key must be hex digits (a passphrase is not a key); make one "
            f"with: {make}"
        ) from None
    if len(key) < 16:
        raise ValueError(f"{path}: the link key has {len(key)} bytes; use 32: {make}")
    weakness = key_weakness(key)
    if weakness is not None:
        raise ValueError(f"{path}: the link key {weakness}: not a random key; make one: {make}")
    if os.name == "posix" and path.stat().st_mode & 0o077:
        raise ValueError(
            f"{path}: the link key is readable by other users (mode "
            f"{path.stat().st_mode & 0o777:03o}); chmod 600 {path}"
        )
    return key


def key_weakness(key: bytes) -> str | None:
    """What betrays a key that was not drawn at random, or None. Each test is one a random
    key of 16 bytes or more fails with a probability below 1e-7 (a 32-byte key: below 1e-13):
    few distinct byte values (00…00, abab…), every byte printable text (a password written
    as hex: (95/256)^16), a steady step between bytes (00 01 02 …), or a repeating block."""
    n = len(key)
    if len(set(key)) < n // 4:  # 32 random bytes hold ~26 distinct values; 00…00 has 1
        return f"has only {len(set(key))} distinct byte values in {n}"
    if all(0x20 <= b < 0x7F for b in key):
        return "is printable text in hex (a password), not random bytes"
    steps = {(b - a) % 256 for a, b in itertools.pairwise(key)}
    if len(steps) < n // 4:
        return f"steps between its bytes take only {len(steps)} values (a sequence)"
    for period in range(1, n // 2 + 1):
        if key[period:] == key[:-period]:
            return f"repeats every {period} bytes"
    return None


class Runtime(Section):
    """How the agent's process runs on the flight computer."""

    realtime_priority: int | None = Field(None, ge=1, le=99)
    """SCHED_FIFO priority (1-99) for the event loop's thread alone (Linux; needs root or
    CAP_SYS_NICE, else a warning and normal scheduling): the loop then preempts everything else
    on the computer, the worker included. Threads and processes it starts get normal
    scheduling. Unset: normal scheduling."""


class Live(Section):
    """The live view sent to the ground while a plan plays and its window is identified: the
    plan's progress, the identification's stage, and strip-chart samples of the commanded and
    measured surfaces and the responses the plan's axis identifies. Best effort: it goes out
    only when no command answer or result is waiting to be sent."""

    period_s: float = Field(1.0, ge=0.0, le=10.0)
    """How often a live message goes out (s); 0: no live view."""
    rate_hz: float = Field(10.0, gt=0.0, le=50.0)
    """Strip-chart samples per second (each message holds those of one period)."""
    max_air_share: float = Field(0.5, gt=0.0, le=1.0)
    """The live view is withheld while this end's radio spent more than this share of the
    last 10 s transmitting, and resumes below 0.8 of it (the ground is told each time): the
    ground's commands share the same air, and an abort waits for whatever is on it."""


class Tuning(Section):
    """ArduPlane's FBWA gains proposed from the nominal model and applied from the ground
    (agent/runtime/gains.py, docs/tuning.md)."""

    max_step: float = Field(2.0, gt=1.0, le=10.0)
    """No gain changes by more than this factor (either way) in one apply: a design further
    away is proposed as a step toward it, every gain moving the same share of the way."""
    track_window_s: float = Field(20.0, ge=5.0, le=300.0)
    """The attitude tracking is judged over this much stabilised flight (FBWA, no plan
    playing) before an apply and after it."""
    track_checks: int = Field(3, ge=1, le=100)
    """How many windows after an apply are judged (each on its own samples): a limit cycle
    can take a while to build."""
    track_degrade: float = Field(2.0, gt=1.0, le=10.0)
    """Applied gains are reverted when the roll or pitch tracking error's rms, or the roll or
    pitch rate's, after the apply is more than this many times the one before it (and above
    its floor)."""
    track_floor_deg: float = Field(1.0, gt=0.0, le=20.0)
    """Attitude tracking errors below this rms (degrees) are never a degradation: sensor noise
    and a light gust."""
    track_rate_floor_dps: float = Field(1.0, gt=0.0, le=100.0)
    """Roll and pitch rates below this rms (degrees per second) are never a degradation; above
    it and `track_degrade` times the rms before, they are a limit cycle the attitude hides."""


class Config(Section):
    """The whole configuration file."""

    identification: IdentificationConfig = IdentificationConfig()
    """The identification core's settings."""
    excitation: Excitation = Excitation()
    """The excitation scheduler's settings and the onboard envelope."""
    sensors: Sensors = Sensors()
    """Sensor ports, rates, calibration."""
    recorder: Recorder = Recorder()
    """Frame assembly, ring buffer, logs."""
    autopilot: Autopilot = Autopilot()
    """The MAVLink link to ArduPlane."""
    link: Link = Link()
    """The XBee air–ground link."""
    runtime: Runtime = Runtime()
    """The agent process's scheduling."""
    live: Live = Live()
    """The live view downlinked during a run."""
    tuning: Tuning = Tuning()
    """Autopilot gains from the model, applied and reverted from the ground."""


def reference(model: type[BaseModel], file: str) -> str:
    """The configuration reference of `model` as Markdown: each section (a TOML table) with
    its description, and each key with its type, default and description — all from the
    models and their field docstrings, so the reference cannot drift from the code."""
    lines = [f"## `{file}`", "", (model.__doc__ or "").strip(), ""]
    _section(model, [], lines)
    return "\n".join(lines).rstrip() + "\n"


def _section(model: type[BaseModel], path: list[str], lines: list[str]) -> None:
    keys, tables = [], []
    for name, info in model.model_fields.items():
        kind, args = info.annotation, typing.get_args(info.annotation)
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            tables.append(([*path, name], kind))
        elif typing.get_origin(kind) is dict and _is_model(args[1]):
            keys.append((name, info))
            tables.append(([*path, name, "<name>"], args[1]))
        else:
            keys.append((name, info))
    if path:
        lines += [f"### `[{'.'.join(path)}]`", "", _text(model.__doc__), ""]
    if keys:
        lines += ["| key | type | default | what it is |", "|---|---|---|---|"]
        for name, info in keys:
            default = info.get_default(call_default_factory=True)
            shown = "required" if info.is_required() else _shown(default)
            text = _text(info.description).replace("|", "\\|")
            lines.append(f"| `{name}` | {_type_name(info.annotation)} | {shown} | {text} |")
        lines.append("")
    for where, kind in tables:
        _section(kind, where, lines)


def _is_model(kind) -> bool:
    return isinstance(kind, type) and issubclass(kind, BaseModel)


def _text(doc: str | None) -> str:
    return " ".join((doc or "").split())


def _type_name(annotation) -> str:
    """A field's type as a reader wants it: `one of "a", "b"`, `int or "auto"`, `float`."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Literal and len(args) == 1:
        return f'`"{args[0]}"`' if isinstance(args[0], str) else f"`{args[0]}`"
    if origin is typing.Literal:
        return "one of " + ", ".join(f'`"{a}"`' if isinstance(a, str) else f"`{a}`" for a in args)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args if a is not type(None)) + (
            " (or unset)" if type(None) in args else ""
        )
    if origin in (tuple, list):
        inner = _type_name(args[0]) if args else "value"
        return f"list of {inner}"
    if origin is dict:
        return f"table of {_type_name(args[1])}"
    return f"`{getattr(annotation, '__name__', annotation)}`"


def _shown(value) -> str:
    if isinstance(value, BaseModel):
        return "(table)"
    if isinstance(value, dict):
        return ", ".join(f"`{k}`" for k in value) if value else "`{}`"
    if value is None:
        return "unset"
    text = repr(value) if not isinstance(value, str) else f'"{value}"'
    return "`" + text.replace("|", "\\|") + "`"


def to_toml(config: BaseModel) -> str:
    """The settings of `config` that differ from the defaults, as a config file that
    `load_config` reads back to an equal config (tomli-w writes what tomllib reads)."""
    import tomli_w

    return tomli_w.dumps(config.model_dump(mode="json", exclude_defaults=True, exclude_none=True))


class ConfigError(Exception):
    """config.toml cannot be used; `problems` lists (key path, reason) pairs."""

    def __init__(self, path: Path, problems: list[tuple[str, str]]):
        self.path = path
        self.problems = problems
        lines = "\n".join(f"  {key}: {reason}" for key, reason in problems)
        super().__init__(f"{path}: invalid configuration\n{lines}")


def load_config(path: str | Path, model: type[BaseModel] = Config):
    """Read and validate a TOML configuration file (the agent's `Config`, or another section
    model such as the ground console's); raise ConfigError saying what is wrong."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(path, [("(file)", "no such file")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, [("(file)", f"cannot be read: {exc}")]) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, [("(syntax)", str(exc))]) from exc
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        problems = [
            (".".join(str(part) for part in err["loc"]) or "(top level)", err["msg"])
            for err in exc.errors()
        ]
        raise ConfigError(path, problems) from exc
