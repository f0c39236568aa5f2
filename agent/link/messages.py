"""What the aircraft and the ground say to each other (pydantic), version 1.

Uplink (ground → air): size a plan, arm a plan, start, abort, identification settings, a
model decision, revert to the previous nominal model, propose, apply and revert autopilot
gains, ping. Downlink (air → ground): status (≈ 1 Hz, best effort), excitation events,
identification results, a plan's sizing, a gain proposal and what became of it,
acknowledgements of commands (with the reason for a refusal), warnings. Every message carries
the protocol version; a receiver refuses other versions with a clear error.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from agent.channels import AxisSet
from agent.excitation.plan import Plan
from agent.ident.document import ModeDocument

VERSION = 1


class LinkMessageError(ValueError):
    """A payload that is not a message of this protocol version."""


class Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    v: int = VERSION


# -- uplink -------------------------------------------------------------------------------


class Arm(Message):
    """Arm this plan (the onboard envelope still decides; the pilot's switch starts it)."""

    kind: Literal["arm"] = "arm"
    plan: Plan


class SizeRequest(Message):
    """How would the aircraft fly this plan? Answered with a Sizing (agent/sizing.py); nothing
    is armed."""

    kind: Literal["size"] = "size"
    plan: Plan


class Start(Message):
    """Start the armed plan where the operator may start it (the switch still gates it)."""

    kind: Literal["start"] = "start"


class Abort(Message):
    kind: Literal["abort"] = "abort"
    reason: str = Field("operator abort", max_length=80)


class IdentSettings(Message):
    """Identification settings (thesis B.2 4.1.1: the operator sets the update period)."""

    kind: Literal["settings"] = "settings"
    axes: AxisSet | None = None
    """The axes every window is identified on, whatever its plan; None: each run on its own
    plan's axes (a periodic window on the configured `[identification] axes`)."""
    markov: int | Literal["auto"] = "auto"
    order: int | Literal["auto"] = "auto"
    batch: bool = False
    # Periodic identification every 5 s to 1 h: inf stopped the periodic loop, 1e-9 spun it.
    update_period_s: float | None = Field(None, ge=5.0, le=3600.0, allow_inf_nan=False)


class Decision(Message):
    """The operator's decision on a candidate model: accept as nominal, or reject."""

    kind: Literal["decision"] = "decision"
    model_id: str = Field(max_length=32)
    accept: bool


class Revert(Message):
    """Go back to the previous nominal model."""

    kind: Literal["revert"] = "revert"


class FrfRequest(Message):
    """Ask for a model's measured frequency response for one input → output pair (answered
    with an Ack, then a FrfReport once the worker has computed it)."""

    kind: Literal["frf-request"] = "frf-request"
    model_id: str = Field(max_length=32)
    input: str = Field(max_length=32)
    output: str = Field(max_length=32)


class GainsRequest(Message):
    """Propose ArduPlane's FBWA roll and pitch gains designed from a model (agent.tune):
    answered with an Ack, then a Gains. Nothing is set."""

    kind: Literal["gains-request"] = "gains-request"
    model_id: str | None = Field(None, max_length=32)
    """None: the nominal model (the full one's, else the lateral and longitudinal ones')."""


class GainsApply(Message):
    """Set a proposal's gains on the autopilot (refused while a plan is armed or playing)."""

    kind: Literal["gains-apply"] = "gains-apply"
    proposal: str = Field(max_length=48)


class GainsRevert(Message):
    """Set the gains the last apply replaced back on the autopilot."""

    kind: Literal["gains-revert"] = "gains-revert"


class Ping(Message):
    kind: Literal["ping"] = "ping"


# -- downlink -------------------------------------------------------------------------------


class Status(Message):
    """Vehicle status, about once a second, latest wins."""

    kind: Literal["status"] = "status"
    time: float
    link_quality: float | None = None
    flight_mode: str | None = None
    airspeed: float | None = None
    """m/s (VFR_HUD)."""
    altitude: float | None = None
    """m (VFR_HUD)."""
    alpha: float | None = None
    """Degrees (AOA_SSA)."""
    beta: float | None = None
    """Degrees (AOA_SSA)."""
    roll: float | None = None
    """Radians, as are pitch and yaw (ATTITUDE)."""
    pitch: float | None = None
    yaw: float | None = None
    excitation: str = "idle"
    identifying: bool = False
    loop_lag_ms: float | None = None
    """The agent's worst event-loop lag since the last status."""
    nominal: dict[str, str] = Field(default_factory=dict)
    """The nominal model id of each identification type that has one."""
    recorder: dict[str, float] = Field(default_factory=dict)
    sensors: dict[str, dict[str, float | str | None]] = Field(default_factory=dict)
    link_fault: str | None = Field(None, max_length=200)
    """Why the aircraft's link cannot obey state-changing commands now (its replay state
    cannot be saved: a full or failing disk); None: it can. An Abort is obeyed regardless."""
    settings: IdentSettings | None = None
    """The identification settings in effect onboard, p and order as they will be used (the
    ground's, else the configuration's); None: an aircraft that does not report them."""


class ExcitationEvent(Message):
    kind: Literal["event"] = "event"
    event: str
    plan_id: str
    time: float
    detail: str = ""


class Result(Message):
    """One identification: modes with their quality indexes, fit, stability, the update
    suggestion and the model matrices (discrete A, B, C, D at dt). The modes are the
    result document's (agent.ident.document.ModeDocument), as the model store keeps them."""

    kind: Literal["result"] = "result"
    model_id: str = Field(max_length=32)
    axes: str
    dt: float
    inputs: list[str]
    outputs: list[str]
    modes: list[ModeDocument]
    tic: list[float]
    tic_avg: float
    stable: bool
    suggest_update: bool
    reasons: list[str] = Field(default_factory=list)
    checks: dict[str, bool] = Field(default_factory=dict)
    """The suggestion's steps as outcomes (agent.models.Suggestion.checks)."""
    tic_jn: float | None = None
    tic_nn: float | None = None
    tic_nj: float | None = None
    A: list[list[float]]
    B: list[list[float]]
    C: list[list[float]]
    D: list[list[float]]


class Live(Message):
    """While a plan plays and its window is identified: the plan's progress, the
    identification's stage, and strip-chart samples. Samples are whole tenths of the display
    unit — degrees for angles and surfaces, degrees per second for rates, m/s, µs, % — so
    MessagePack carries each in one to three bytes; None: no data. A commanded surface is
    `<control>_cmd` (its deflection from trim); while a plan plays, the surfaces it commands
    are shown from their trim too (their mean over the 0.5 s before it started)."""

    kind: Literal["live"] = "live"
    time: float
    """Of the first sample."""
    dt: float
    plan_id: str | None = Field(None, max_length=32)
    plan_fraction: float | None = None
    """The share of the plan played (None: none playing)."""
    plan_s: float | None = None
    stage: str = Field("", max_length=24)
    """The identification's: "recording margin", "queued", "identifying", "comparing with
    nominal" ("" none)."""
    stage_s: float | None = None
    """Time in that stage so far."""
    stage_expected_s: float | None = None
    """How long that stage should take: the margin's length, or the last such stage's on
    these axes scaled by the record's length (None: not known yet)."""
    tenths: dict[str, list[int | None]] = Field(default_factory=dict, max_length=16)


# The most frequency points a FrfReport carries (log-spaced among the excited ones): about
# 1.8 kB of MessagePack, seven frames.
FRF_POINTS = 48


class FrfReport(Message):
    """A model's measured frequency response for one pair, at the frequencies its input
    excited in the model's own data (`agent.ident.frf`): magnitude, phase and coherence."""

    kind: Literal["frf"] = "frf"
    model_id: str = Field(max_length=32)
    input: str = Field(max_length=32)
    output: str = Field(max_length=32)
    averaging: str = Field(max_length=16)
    segments: int
    freq_hz: list[float] = Field(max_length=FRF_POINTS)
    mag_db: list[float] = Field(max_length=FRF_POINTS)
    phase_deg: list[float] = Field(max_length=FRF_POINTS)
    coherence: list[float | None] = Field(max_length=FRF_POINTS)


class Failure(Message):
    """An identification that failed, and why (the agent keeps flying)."""

    kind: Literal["failure"] = "failure"
    model_id: str = Field(max_length=32)
    axes: str
    reason: str = Field(max_length=300)


class Ack(Message):
    """The answer to a command: done, or refused with the reason."""

    kind: Literal["ack"] = "ack"
    ref: int
    ok: bool
    reason: str = ""


class SizedControl(BaseModel):
    """One control of a sized plan: its largest deflection, the factor on the plan's own
    amplitude, and what set it (a target, a limit, the build-up)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    control: str = Field(max_length=16)
    amplitude: float
    unit: Literal["deg", "%"]
    factor: float
    limited_by: str = Field(max_length=80)


class Sizing(Message):
    """The answer to a SizeRequest: the plan sized to the aircraft (arm it as it is), how,
    from which model, the response predicted, and where that leaves the envelope."""

    kind: Literal["sizing"] = "sizing"
    plan: Plan
    source: str = Field(max_length=120)
    build_up: bool = False
    """No model sized it: the plan's amplitudes times the build-up share (a calibration run)."""
    controls: list[SizedControl]
    predicted: dict[str, float] = Field(default_factory=dict)
    """Each predicted peak by quantity (agent.sizing.QUANTITIES); empty: no model yet."""
    corrections: dict[str, float] = Field(default_factory=dict)
    """Quantity → how much more the model's own data moved than it predicts (≥ 1), by which
    its predictions were scaled."""
    unexplained: dict[str, float] = Field(default_factory=dict)
    """Quantity → the largest excursion of the model's data no input explains (turbulence,
    drift), added to the predicted peaks the envelope is checked against."""
    refusals: list[Annotated[str, Field(max_length=200)]] = Field(default_factory=list)


class GainRow(BaseModel):
    """One parameter of a proposal: what the autopilot holds now, what the design asks, and
    what the proposal sets (a step toward the design where the change per step is limited)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str = Field(max_length=16)
    current: float | None = None
    """None: the autopilot did not give it."""
    designed: float
    proposed: float | None = None
    """None: this axis is not proposed (`Gains.refused` says why)."""


class LoopPrediction(BaseModel):
    """One axis's predicted loop with a set of gains (agent.tune.assess)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    axis: Literal["roll", "pitch"]
    gains: Literal["current", "proposed"]
    crossover_rad_s: float | None = None
    phase_margin_deg: float | None = None
    gain_margin_db: float | None = None
    """None: infinite (the loop never loses stability with more gain)."""
    delay_margin_s: float | None = None
    rejection_rad_s: float | None = None
    rise_s: float | None = None
    overshoot_pct: float | None = None
    rise_down_s: float | None = None
    """The step the other way where the linkage's travel differs each way (None: as rise_s)."""
    overshoot_down_pct: float | None = None
    sound: bool = False
    """Whether the whole loop keeps 6 dB and 45° (MIL-F-9490D)."""
    stable: bool = True
    """False: these gains do not hold the axis at all (the margins are then left out)."""


class Gains(Message):
    """A proposal: the gains designed from a model beside the autopilot's, with each set's
    predicted loops; apply it by its id (GainsApply)."""

    kind: Literal["gains"] = "gains"
    proposal: str = Field(max_length=48)
    model_id: str = Field(max_length=32)
    rows: list[GainRow]
    loops: list[LoopPrediction]
    share: dict[str, float] = Field(default_factory=dict)
    """Axis → the share of the way to the design the proposal goes (1: the design)."""
    refused: list[Annotated[str, Field(max_length=200)]] = Field(default_factory=list)
    notes: list[Annotated[str, Field(max_length=200)]] = Field(default_factory=list)


class GainsReport(Message):
    """What became of the autopilot's gains: applied, reverted (on command or by the
    tracking self-check), or failed (and what the autopilot holds after it)."""

    kind: Literal["gains-report"] = "gains-report"
    action: Literal["applied", "reverted", "failed"]
    proposal: str | None = Field(None, max_length=48)
    values: dict[str, float] = Field(default_factory=dict)
    """The gains as read back from the autopilot."""
    reason: str = Field("", max_length=200)


class Notice(Message):
    """A warning for the operator."""

    kind: Literal["warning"] = "warning"
    text: str = Field(max_length=200)


Uplink = (
    Arm
    | SizeRequest
    | Start
    | Abort
    | IdentSettings
    | Decision
    | Revert
    | FrfRequest
    | GainsRequest
    | GainsApply
    | GainsRevert
    | Ping
)
Downlink = (
    Status
    | Live
    | ExcitationEvent
    | Result
    | Sizing
    | FrfReport
    | Gains
    | GainsReport
    | Failure
    | Ack
    | Notice
    | Ping
)
Message = Annotated[
    Arm
    | SizeRequest
    | Start
    | Abort
    | IdentSettings
    | Decision
    | Revert
    | FrfRequest
    | GainsRequest
    | GainsApply
    | GainsRevert
    | Ping
    | Status
    | Live
    | ExcitationEvent
    | Result
    | Sizing
    | FrfReport
    | Gains
    | GainsReport
    | Failure
    | Ack
    | Notice,
    Field(discriminator="kind"),
]
_ADAPTER = TypeAdapter(Message)


def to_dict(message: Message) -> dict:
    """Plain values with defaults left out (kind, version and a plan's signal kinds stay)."""
    data = message.model_dump(mode="json", exclude_defaults=True)
    data |= {"kind": message.kind, "v": message.v}
    if isinstance(message, Arm | SizeRequest | Sizing):
        data["plan"] = message.plan.to_compact()
    return data


def from_dict(data: object) -> Message:
    """A message from its decoded form; LinkMessageError for another version or a bad one."""
    if not isinstance(data, dict):
        raise LinkMessageError(f"a message is a map, got {type(data).__name__}")
    version = data.get("v", VERSION)
    if version != VERSION:
        raise LinkMessageError(
            f"link protocol version {version} is not supported (this end speaks {VERSION}): "
            "update the other end"
        )
    try:
        return _ADAPTER.validate_python(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise LinkMessageError(f"not a valid message: {where}: {first['msg']}") from exc
